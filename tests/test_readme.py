"""Every command and snippet of the README and the getting-started page runs as written
(issue 47: the README's ``flexarm calibrate`` line failed; the docs pages' examples:
tests/test_docs.py).  The commands run in order in one folder, as a reader would run
them from the repository's root: a folder whose ``campaigns/`` and ``examples/`` are the
repository's, so that what they write (``results/``) stays out of the checkout.  The
``make`` targets they show are checked to exist (``make -n``): running ``make test``
inside the test suite would run it again."""
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)
sys.path.insert(0, str(ROOT / "tests"))
from cli_testing import flexarm  # noqa: E402
from test_docs import code_blocks  # noqa: E402

SNIPPETS = [body for lang, body in BLOCKS if lang == "python"
            and not re.match(r"# [\w./-]+\.py\n", body)]


def shown_lines() -> list[str]:
    """The shell lines the README and the getting-started page show, in their order,
    without their comments."""
    blocks = [body for lang, body in BLOCKS if lang == "sh"]
    blocks += code_blocks(ROOT / "docs" / "getting-started.rst", "sh")
    return [line.split("#")[0].strip() for block in blocks for line in block.splitlines()
            if line.split("#")[0].strip()]


LINES = list(dict.fromkeys(shown_lines()))  # a command shown twice runs once
COMMANDS = [line for line in LINES if line.startswith("flexarm ")]
#: What the commands slower than ~10 s took on two shared cores (a fresh folder, numba's
#: cache warm), and the command that needs one of them first: `make test-all` runs them.
SLOW = {"flexarm reproduce-paper --lab --no-stability": "460 s",
        "flexarm attribute campaigns/kinematics.toml": "186 s",
        "flexarm campaign campaigns/mismatch.toml --workers 2": "52 s",
        "flexarm campaign campaigns/arms.toml --workers 2": "45 s",
        "flexarm report results/arms": "reads the campaign's folder",
        "flexarm report results/mismatch": "reads the campaign's folder",
        "flexarm stability campaigns/paper.toml --tolerance 0.005 --out results/paper/stability":
        "STABILITY",
        "flexarm validity campaigns/paper.toml": "VALIDITY",
        "flexarm verify campaigns/robust.toml --mode estimate": "ESTIMATE",
        "flexarm verify campaigns/robust.toml --mode falsify --requirement tracking": "FALSIFY",
        "flexarm calibrate examples/calibration/tracking.csv examples/calibration/moving.csv "
        "--config examples/calibration/arm.toml": "75 s",
        "flexarm attribute examples/lab-arm.toml --factors friction,drive,bandwidth,plant":
        "12 s",
        "flexarm calibrate examples/calibration/reversals.csv "
        "--config examples/calibration/friction.toml": "64 s",
        "flexarm baseline check": "BASELINE"}


def test_the_lines_shown_are_commands_and_targets():
    """Nothing but ``flexarm`` commands and ``make`` targets is shown to be run; every
    slow command listed is shown (the list cannot go stale)."""
    assert {line.split()[0] for line in LINES} <= {"flexarm", "make"}, LINES
    assert set(SLOW) <= set(COMMANDS), sorted(set(SLOW) - set(COMMANDS))
    assert any(line.startswith("flexarm calibrate ") for line in COMMANDS)


@pytest.mark.parametrize("line", [line for line in LINES if line.startswith("make ")])
def test_the_make_targets_shown_exist(line):
    proc = subprocess.run([*line.split()[:1], "-n", *line.split()[1:]], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


@pytest.fixture(scope="module")
def root_like(tmp_path_factory):
    """A folder that reads as the repository's root: its campaigns and examples."""
    folder = tmp_path_factory.mktemp("readme")
    for name in ("campaigns", "examples"):
        (folder / name).symlink_to(ROOT / name)
    return folder


@pytest.mark.parametrize("line", [pytest.param(line, marks=[pytest.mark.slow] * (line in SLOW))
                                  for line in COMMANDS])
def test_the_commands_shown_run_as_written(line, root_like):
    proc = flexarm(root_like, *shlex.split(line)[1:], timeout=3600)
    assert proc.returncode == 0, f"{line}: exit {proc.returncode}\n{proc.stderr[-3000:]}"


@pytest.mark.parametrize("snippet", SNIPPETS, ids=[f"python{i}" for i in range(len(SNIPPETS))])
def test_python_snippets_run(snippet, tmp_path):
    proc = subprocess.run([sys.executable, "-c", snippet], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_the_readme_and_getting_started_say_where_flexarm_is():
    """Issue 47: after `make demo`, "flexarm: command not found": the pages said nothing
    of the virtual environment the command is installed in."""
    start = (ROOT / "docs" / "getting-started.rst").read_text()
    head = README.split("## From the command line")[0]
    for text in (head, start):
        assert "source .venv/bin/activate" in text and ".venv/bin/flexarm" in text


def test_the_time_and_disk_the_readme_states_are_the_measured_ones():
    """Issue 46: the README states the main job's time and disk on two cores; they are the
    job's measured profile (`validation.cli.job_clock`, from bench/bench_paper.py), which
    the command's own estimate uses — the README cannot drift from it."""
    from validation.cli.job_clock import PAPER, PAPER_COLD_START, PAPER_DISK_MB
    minutes = round((PAPER_COLD_START + sum(seconds for _, seconds in PAPER)) / 60)
    assert f"about {minutes} min on two cores" in " ".join(README.split())
    assert f"{PAPER_DISK_MB:.0f} MB in `results/paper`" in " ".join(README.split())


def test_the_size_of_a_run_the_readme_states_is_measured(tmp_path):
    """The run size the README states is measured: a 20 s run keeping every signal at
    Ts = 1 ms (the default scenario: ``flexarm run``'s) stores what it says, within 10 %
    (the compressed file moves a little with its signals' values)."""
    from validation import cli
    stated = re.search(r"a 20 s run that keeps every signal at Ts = 1 ms stores ([\d.]+) MB",
                       " ".join(README.split()))
    assert stated, "the README states no run size"
    assert cli.main(["run", "--duration", "20", "--out", str(tmp_path)]) == 0
    (path,) = (tmp_path / "runs").glob("*.npz")
    assert abs(path.stat().st_size / 1e6 / float(stated[1]) - 1) <= 0.1, path.stat().st_size
