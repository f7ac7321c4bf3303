# Two commands matter: `make demo` and `make test`.  Both bootstrap .venv from PyPI.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PYTEST := $(BIN)/python -m pytest

.PHONY: demo test test-all bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,cluster]'
	touch $(STAMP)

# The main job: the paper's scenario on both plants, its claims table and the report.
# Exit status 1 means some runs failed (e.g. Exudyn's solver on an arm already diverging):
# they are named in the output and the report, and the demo has done its job.
demo: $(STAMP)
	$(BIN)/flexarm reproduce-paper --out results/paper || { rc=$$?; [ $$rc -eq 1 ] || exit $$rc; \
	  echo "make demo: done; the failed runs named above are results too (see results/paper/report)"; }

# pytest exits 5 when it collects nothing: say so and fail rather than pass silently.
test: $(STAMP)
	$(PYTEST) || { rc=$$?; [ $$rc -ne 5 ] || echo "make test: pytest collected no tests"; exit $$rc; }

test-all: $(STAMP)
	$(PYTEST) -m "slow or not slow" || { rc=$$?; [ $$rc -ne 5 ] || echo "make test-all: pytest collected no tests"; exit $$rc; }

bench: $(STAMP)
	for script in bench/bench_*.py; do $(BIN)/python $$script || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache bench/results
	find . -name __pycache__ -prune -exec rm -rf {} +
