"""What the tests share: a folder of plug-in modules importable by this process (and by
the `flexarm` commands the tests start there), a small results folder with its report,
and the kernels compiled once before the test processes start."""
import fcntl
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from validation.batch.fingerprint import forget_plugins


def pytest_configure(config):
    """Before pytest-xdist starts its test processes: compile the kernels most tests use
    in two processes side by side (`warm_kernels`), so that no test process pays for a
    compile another has paid for.  A serial run compiles as it goes."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", None) \
            or config.getoption("collectonly"):
        return
    start = time.perf_counter()
    script = Path(__file__).with_name("warm_kernels.py")
    parts = [subprocess.Popen([sys.executable, str(script), str(k)], stderr=subprocess.PIPE,
                              text=True) for k in (0, 1)]
    failed = [err for p in parts if (err := p.communicate()[1]) and p.returncode]
    print(f"kernels compiled or loaded in {time.perf_counter() - start:.0f} s "
          "(tests/warm_kernels.py)", file=sys.stderr)
    for err in failed:  # the tests that use the kernel will say what is wrong
        print("tests/warm_kernels.py failed:", err.strip().splitlines()[-1], file=sys.stderr)



#: A plug-in plant module (write it as ``labplants.py``): a finer assumed-modes arm playing
#: the truth, ``plant.kind = "labplants:FineArm"`` — a truth plant that costs little.
FINE_ARM_PLANT = textwrap.dedent('''
    """A finer assumed-modes arm playing the truth: the reduced plant with its own modes."""
    from reduced_model import Plant, ReducedPlant


    class FineArm(ReducedPlant):
        role = "truth"

        def __init__(self, params, *, model, sensors, Ts, modes=3):
            super().__init__(params, model=model, sensors=sensors, Ts=Ts,
                             modes_per_link=(modes, modes), step=2.5e-4)


    class NoRole(Plant):
        """A plant that forgot to declare its role."""


    class Half(Plant):
        """A plant with a role and little else."""

        role = "truth"
''')

def write_files(folder: Path, files: dict[str, str]) -> Path:
    """Write ``files`` ({path relative to ``folder``: text}) into ``folder``; returns it."""
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    return folder


@pytest.fixture()
def plugin_lab(tmp_path, monkeypatch):
    """``plugin_lab(files)``: the plug-in modules ``files`` written into a fresh folder on
    ``sys.path``, no earlier copy of them imported, the plug-in fingerprint cache empty
    (before and after the test); returns the folder."""
    def make(files: dict[str, str]) -> Path:
        write_files(tmp_path, files)
        monkeypatch.syspath_prepend(str(tmp_path))
        modules = {str(Path(name).with_suffix("")).replace("/", ".").removesuffix(".__init__")
                   for name in files}
        for name in [m for m in sys.modules
                     if any(m == mod or m.startswith(mod + ".") for mod in modules)]:
            monkeypatch.delitem(sys.modules, name)
        forget_plugins()
        return tmp_path
    yield make
    forget_plugins()


#: A small campaign with its report: the paper's system (so named, that the claims and the
#: summary are drawn) on both plants, and a sweep of the control period.
REPORT_SPEC = {
    "name": "rep", "description": "report test",
    "scenario": {"duration": 3.0, "transient": 1.0, "observer": {"kind": "smo-bl"},
                 "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}},
    "report": {"figures": ["pbc+smo-paper"]},
    "sweep": [{"name": "both", "grid": {"plant.kind": ["reduced", "exudyn"]},
               "zip": {"name": ["pbc+smo-paper"]}},
              # Ts = 8 ms is beyond the sampled loop's limit (~2.8 ms): it diverges.
              {"name": "ts", "grid": {"Ts": [5e-4, 1e-3, 8e-3], "plant.step": [5e-4]}}]}


@pytest.fixture(scope="session")
def reported(tmp_path_factory) -> Path:
    """A results folder of `REPORT_SPEC` with its report (the report's tests and the docs'
    findings page read it): made once per test session, by whichever test process needs
    it first, and copied into each process's own folder (its tests may write there)."""
    from validation.batch.campaign import campaign_from_mapping
    from validation.batch.queue import run_campaign
    from validation.report.report import write_report
    session = tmp_path_factory.getbasetemp()  # under pytest-xdist: this process's part
    shared = (session.parent if "PYTEST_XDIST_WORKER" in os.environ else session) / "reported"
    with open(f"{shared}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the other process waits for it to be made
        if not shared.exists():
            making = shared.with_name("reported-making")
            shutil.rmtree(making, ignore_errors=True)
            run_campaign(campaign_from_mapping(REPORT_SPEC), making, progress=False)
            write_report(making, progress=False)
            making.rename(shared)
    out = tmp_path_factory.mktemp("report")
    shutil.copytree(shared, out, dirs_exist_ok=True)
    return out
