"""Reading a results folder never runs code the folder names or holds: `report`, `show`,
`export` and `repair` of runs made with plug-in laws import none of them (known bad: they
imported the observer plug-in a stored run named, and `cd OUT && flexarm report .` ran a
module shipped in the folder), and a folder's own modules cannot stand in for a library."""
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import write_files
from validation.batch.store.folder import ResultStore

LAWS = {
    "labctl.py": textwrap.dedent('''
        from controllers import JointPD

        class Ctl(JointPD):
            """A plug-in controller (the built-in PD under another name)."""
    '''),
    "labobs.py": textwrap.dedent('''
        from controllers import PaperSMO

        class Obs(PaperSMO):
            """A plug-in observer (the paper's SMO under another name)."""
    '''),
}
SCENARIO = textwrap.dedent('''
    duration = 0.5
    transient = 0.1
    controller = { kind = "labctl:Ctl" }
    observer = { kind = "labobs:Obs" }
''')
#: What each module does if anything imports it once the runs are stored.
EVIL = "import pathlib; pathlib.Path(__file__).with_name('IMPORTED-' + __name__).touch()\n"
FLEXARM = Path(sys.executable).with_name("flexarm")  # the console script: no cwd on sys.path


def flexarm(cwd, *args):
    return subprocess.run([str(FLEXARM), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)


# slow (15 s: test_store.py's test_reading_a_results_folder_never_imports_a_plugin keeps the
# rule in make test).
@pytest.mark.slow
def test_reading_a_folder_never_imports_the_plugins_it_names(tmp_path):
    lab = write_files(tmp_path, {**LAWS, "s.toml": SCENARIO})
    made = flexarm(lab, "run", "--config", "s.toml", "--out", "out")
    assert made.returncode == 0, made.stderr
    (row,) = ResultStore(lab / "out").rows()
    assert row.timings["observer_measured"]  # what the report marks, recorded by the run
    write_files(lab, {name: EVIL for name in LAWS})  # the plug-ins now run code on import
    write_files(lab / "out", {"jinja2.py": EVIL, "matplotlib.py": EVIL, "numpy.py": EVIL})
    for cwd, args in ((lab, ["report", "out"]), (lab, ["show", f"out/{row.run_id}"]),
                      (lab, ["export", "out"]), (lab, ["repair", "out"]),
                      (lab / "out", ["report", "."])):
        proc = flexarm(cwd, *args)
        assert proc.returncode == 0, (args, proc.stderr)
        imported = sorted(p.name for p in lab.rglob("IMPORTED-*"))
        assert imported == [], (args, imported)
