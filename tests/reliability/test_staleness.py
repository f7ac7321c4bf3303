"""A plug-in's code fingerprint covers the project-local modules it imports — helpers
imported by name, from a package, relatively — so editing a helper makes the stored runs
stale; the fingerprint is found without importing anything."""
import json
import os
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest

from validation.batch.campaign import campaign_from_mapping, run_campaign
from validation.batch.executor import SerialRunner
from validation.batch.fingerprint import plugin_sources, run_fingerprint
from validation.batch.store import ResultStore
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping

LAW = textwrap.dedent('''
    """A PD law whose gains live in helper modules."""
    import pathlib

    import numpy as np

    import labgains
    from labpkg.tuning import KD
    from labpkg import shapes

    pathlib.Path(__file__).with_name("IMPORTED").write_text("imported")


    class HelperPD:
        def __init__(self, model):
            pass

        def __call__(self, t, x, ref):
            n = x.shape[0] // 2
            theta_d, dtheta_d, _ = ref(t)
            return shapes.scaled(labgains.KP * (theta_d - x[:2]) + KD * (dtheta_d - x[n:n + 2]))
''')
FILES = {
    "lablaw.py": LAW,
    "labgains.py": "KP = 30.0\n",
    "labpkg/__init__.py": "",
    "labpkg/tuning.py": "from .limits import CAP\nKD = min(18.0, CAP)\n",
    "labpkg/limits.py": "CAP = 100.0\n",
    "labpkg/shapes.py": "def scaled(tau):\n    return 1.0 * tau\n",
    "unrelated.py": "X = 1\n",
}


@pytest.fixture()
def lab(plugin_lab):
    return plugin_lab(FILES)


CONFIG = {"duration": 1.0, "transient": 0.5, "controller": {"kind": "lablaw:HelperPD"}}


def test_the_fingerprint_covers_every_local_module_the_plugin_imports(lab):
    files = {p.relative_to(lab).as_posix() for p in plugin_sources("lablaw:HelperPD")}
    # Its own module, its helpers by name, from a package, relatively and transitively,
    # and the package's __init__ — not numpy, not the standard library, not a file it
    # does not import.
    assert files == {"lablaw.py", "labgains.py", "labpkg/__init__.py", "labpkg/tuning.py",
                     "labpkg/limits.py", "labpkg/shapes.py"}
    assert not (lab / "IMPORTED").exists() and "lablaw" not in sys.modules  # not imported


@pytest.mark.parametrize("edited, changes", [
    ("labgains.py", True), ("labpkg/tuning.py", True), ("labpkg/limits.py", True),
    ("labpkg/shapes.py", True), ("labpkg/__init__.py", True), ("unrelated.py", False)])
def test_editing_a_helper_changes_the_fingerprint(lab, edited, changes):
    config = json.loads(json.dumps(scenario_to_mapping(scenario_from_mapping(CONFIG))))
    before = run_fingerprint(config)
    (lab / edited).write_text((lab / edited).read_text() + "# edited\n")
    assert (run_fingerprint(config) != before) == changes


def test_a_run_made_before_a_helper_edit_is_stale_and_redone(lab, tmp_path):
    campaign = campaign_from_mapping({"name": "helper", "scenario": CONFIG})
    out = tmp_path / "out"
    first = run_campaign(campaign, out, runner=SerialRunner(), progress=False)
    assert first.ok == 1
    (row,) = ResultStore(out).rows()
    again = run_campaign(campaign, out, runner=SerialRunner(), progress=False)
    assert (again.skipped, again.done) == (1, 0)  # same code: reused
    (lab / "labgains.py").write_text("KP = 60.0\n")  # a new gain, in the helper only
    for module in ("lablaw", "labgains"):
        sys.modules.pop(module, None)  # this process runs the edited code too
    edited = run_campaign(campaign, out, runner=SerialRunner(), progress=False)
    assert edited.stale == [row.run_id] and edited.ok == 1
    (redone,) = ResultStore(out).rows()
    assert redone.fingerprint != row.fingerprint
    # The stored result is the edited law's: twice the stiffness, another tracking error.
    assert not np.isclose(redone.metrics["track_max_1"], row.metrics["track_max_1"],
                          rtol=1e-3)


def test_a_helper_python_cannot_parse_is_hashed_not_followed(lab):
    (lab / "oldhelper.py").write_text("print 'python 2'\n")
    (lab / "lablaw.py").write_text(LAW + "\ntry:\n    import oldhelper\nexcept SyntaxError:\n"
                                         "    oldhelper = None\n")
    files = {p.relative_to(lab).as_posix() for p in plugin_sources("lablaw:HelperPD")}
    assert "oldhelper.py" in files  # no SyntaxError out of the fingerprint
    config = json.loads(json.dumps(scenario_to_mapping(scenario_from_mapping(CONFIG))))
    before = run_fingerprint(config)
    (lab / "oldhelper.py").write_text("print 'python 2, edited'\n")
    assert run_fingerprint(config) != before


ZIP_LAW = textwrap.dedent('''
    class ZipPD:
        """A PD law shipped in a zip archive."""
        def __init__(self, model):
            pass

        def __call__(self, t, x, ref):
            n = x.shape[0] // 2
            theta_d, dtheta_d, _ = ref(t)
            return 30.0 * (theta_d - x[:2]) + 18.0 * (dtheta_d - x[n:n + 2])
''')


def _zip(path, text: str) -> None:
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("ziplaws.py", text)


def test_a_plugin_from_a_zip_archive_runs_and_its_archive_is_its_fingerprint(tmp_path):
    """Known-bad (issue 32): with the archive on PYTHONPATH (ordinary Python), the run
    ran, then storing it failed: "laws.zip/ziplaws.py: Not a directory" (the fingerprint
    read the module as a file), exit 1.  Now the archive is hashed whole: the run is
    stored, and editing the archive makes it stale."""
    _zip(tmp_path / "laws.zip", ZIP_LAW)
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "laws.zip")}
    done = subprocess.run([sys.executable, "-m", "validation.cli", "run", "--controller",
                           "ziplaws:ZipPD", "--duration", "0.2", "--out", "out"],
                          cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    (row,) = ResultStore(tmp_path / "out").rows()
    assert row.status == "ok"
    fingerprint = [sys.executable, "-c", "import sys, json; from validation.batch."
                   "fingerprint import run_fingerprint; print(run_fingerprint("
                   "json.loads(sys.argv[1])))", json.dumps(row.config)]
    same = subprocess.run(fingerprint, env=env, capture_output=True, text=True, check=True)
    assert same.stdout.strip() == row.fingerprint
    _zip(tmp_path / "laws.zip", ZIP_LAW.replace("30.0", "60.0"))
    edited = subprocess.run(fingerprint, env=env, capture_output=True, text=True, check=True)
    assert edited.stdout.strip() != row.fingerprint
