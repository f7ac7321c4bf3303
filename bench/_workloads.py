"""Workloads several benches measure, defined once so that their numbers compare, and
how a bench gets the tree of another revision to measure against."""
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The command line of the tree in the current directory, in a fresh interpreter:
#: ``python -c CLI ARGS`` (works for revisions whose CLI predates the console script).
CLI = "import sys; from validation.cli import main; raise SystemExit(main(sys.argv[1:]))"

#: 48 × 5 s reduced runs (PBC with two SMOs, six payloads, four seeds).
REDUCED_48 = """name = "bench-reduced"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.2, 0.3, 0.5, 0.8]
grid."observer.kind" = ["smo-paper", "smo-bl"]
grid.seed = [1, 2, 3, 4]
"""

#: 8 × 20 s truth-plant runs (PBC + sign SMO, four payloads, two seeds).
TRUTH_8 = """name = "bench-exudyn"
[scenario]
plant.kind = "exudyn"
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.5, 1.0]
grid.seed = [1, 2]
"""

#: 48 × 5 s reduced runs of one law pair (PBC + sign SMO: six payloads, eight seeds), so
#: that a one-run campaign of the same laws is their fair start (the kernels it loads are
#: all the campaign needs).
REDUCED_ONE_LAW = """name = "bench-coordinator"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.1, 0.2, 0.3, 0.5, 0.8]
grid.seed = [1, 2, 3, 4, 5, 6, 7, 8]
"""

#: One run of `REDUCED_ONE_LAW`'s laws: its campaign is the command's fixed start.
ONE_RUN = """name = "bench-one"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
"""


#: Short reduced runs keeping metrics only, one noise seed each (PBC + sign SMO, noisy
#: encoders): ``METRICS_ONLY.format(duration=…, transient=…, requirement=…, seeds=[…])``.
#: One arm for every run: expanding a run costs ~0.3 ms; a random arm per run (e.g. a
#: random payload) costs ~3.6 ms each, the scenario check of every distinct arm.
METRICS_ONLY = """name = "large"
[scenario]
duration = {duration}
transient = {transient}
observer.kind = "smo-paper"
sensors.encoder_noise = 1e-4
[keep]
signals = "none"
{requirement}[[sweep]]
name = "seeds"
grid.seed = {seeds}
"""


def extract(rev: str, folder: Path) -> Path:
    """The tree of revision ``rev`` extracted into ``folder`` (``git archive``: no
    worktree, no checkout)."""
    folder.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder
