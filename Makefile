# Two commands matter: `make demo` and `make test`.  Both bootstrap .venv from PyPI with
# the pinned set in constraints.txt (every package, transitive ones, pip and setuptools
# included); `make lock` regenerates it from what PyPI serves today, `make test-latest`
# runs the tests against that newest set without touching .venv.  `make docs` builds the
# documentation site into docs/_build/html (index.html), running the examples gallery.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The tests run in two processes (pytest-xdist), each test file in one of them: on two
# cores the suite takes ~55 % of its serial time.  PARALLEL= runs it serially.  A test
# process that crashes ends the suite: pytest-xdist 3.8 hangs for ever when it replaces a
# crashed process under --dist loadfile (pytest-xdist issues 784 and 1323).
PARALLEL ?= -n 2 --dist loadfile --max-worker-restart=0
PYTEST := $(BIN)/python -m pytest $(PARALLEL)
EXTRAS := test,cluster,fmi
# The docs extra is pinned with the rest but installed only by `make docs`: the test
# suite needs none of Sphinx.
DOCS_EXTRAS := $(EXTRAS),docs
DOCS_STAMP  := $(VENV)/.installed-docs
PINS   := constraints.txt

.PHONY: demo findings test test-all test-latest lock bench docs clean

# pip and setuptools first (pinned), then the project against the venv's own setuptools
# (no build isolation: the build backend is pinned too).
$(STAMP): pyproject.toml $(PINS)
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -c $(PINS) pip setuptools
	$(BIN)/python -m pip install --quiet -c $(PINS) --no-build-isolation -e '.[$(EXTRAS)]'
	touch $(STAMP)

# The main job: the paper's scenario on both plants, its claims table and the report.  It
# prints a short summary (the verdicts, where the files are) and fails only when a verdict
# is missing: runs that fail but decide nothing (Exudyn's solver on an arm far beyond its
# stability limit) are counted in the summary and named in the report.
demo: $(STAMP)
	$(BIN)/flexarm reproduce-paper --out results/paper

# The findings beyond the paper's own arm, for the docs' findings page: the paper's claims
# on the lab arm (friction, drives) and how much of the reduced-vs-truth gap the paper's
# linear kinematics explain.  Not part of the main job: each takes minutes.
findings: $(STAMP)
	$(BIN)/flexarm reproduce-paper --lab --no-stability --out results/lab
	$(BIN)/flexarm attribute campaigns/kinematics.toml --out results/kinematics

# pytest exits 5 when it collects nothing: say so and fail rather than pass silently.
test: $(STAMP)
	$(PYTEST) || { rc=$$?; [ $$rc -ne 5 ] || echo "make test: pytest collected no tests"; exit $$rc; }

test-all: $(STAMP)
	$(PYTEST) -m "slow or not slow" || { rc=$$?; [ $$rc -ne 5 ] || echo "make test-all: pytest collected no tests"; exit $$rc; }

# The suite against the newest releases PyPI serves (no pins), in its own .venv-latest:
# drift is seen here before a user meets it.  It prints the versions it tested.
test-latest:
	rm -rf .venv-latest
	$(PYTHON) -m venv .venv-latest
	.venv-latest/bin/python -m pip install --quiet --upgrade pip setuptools
	.venv-latest/bin/python -m pip install --quiet --upgrade --no-build-isolation -e '.[$(EXTRAS)]'
	.venv-latest/bin/python -m pip freeze --exclude-editable | tr '\n' ' '; echo
	.venv-latest/bin/python -m pytest $(PARALLEL)

# Regenerate the pins: a fresh environment with the newest releases of everything the
# project needs (pyproject.toml's ranges), frozen.  Commit the result after `make test`.
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip setuptools
	.venv-lock/bin/python -m pip install --quiet --no-build-isolation '.[$(DOCS_EXTRAS)]'
	{ echo "# Every package make demo / make test / make docs install, pinned (regenerate: make lock)."; \
	  echo "# $$(.venv-lock/bin/python --version), $$(date -u +%Y-%m-%d)"; \
	  .venv-lock/bin/python -m pip freeze --all --exclude flexarm-validation; } > $(PINS)
	rm -rf .venv-lock build

$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -c $(PINS) --no-build-isolation -e '.[$(DOCS_EXTRAS)]'
	touch $(DOCS_STAMP)

# Warnings are errors (-W) and every cross-reference must resolve (-n); --keep-going
# lists them all before failing.  The gallery's examples run during the build.
docs: $(DOCS_STAMP)
	$(BIN)/python -m sphinx -W -n --keep-going -b html docs docs/_build/html
	@echo "make docs: open docs/_build/html/index.html"

bench: $(STAMP)
	for script in bench/bench_*.py; do $(BIN)/python $$script || exit 1; done

clean:
	rm -rf $(VENV) .venv-latest .venv-lock build *.egg-info .pytest_cache bench/results
	rm -rf docs/_build docs/_generated docs/auto_examples docs/reference/api
	find . -name __pycache__ -prune -exec rm -rf {} +
