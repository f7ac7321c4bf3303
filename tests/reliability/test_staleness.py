"""Nothing stale is reused: a plug-in's code fingerprint covers the modules it imports —
helpers imported by name, from a package, relatively, lazily, from bytecode, inside the
project's packages, installed with pip — so editing or upgrading one makes the stored
runs stale; the fingerprint is found without importing anything.  Numba's caches follow
the same sources (project kernels and plug-ins, wherever the caches are)."""
import hashlib
import json
import os
import py_compile
import site
import subprocess
import sys
import textwrap
from pathlib import Path
import zipfile

import numpy as np
import pytest

from validation.batch.campaign import campaign_from_mapping

from validation.batch.queue import run_campaign
from validation.batch.executor import SerialRunner
from reduced_model.code import kernel_keys
from validation.batch.fingerprint import (_ROOT, forget_plugins, plugin_sources,
                                          run_fingerprint)
from validation.batch.store.folder import ResultStore
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping

from conftest import write_files

LAW = textwrap.dedent('''
    """A PD law whose gains live in helper modules."""
    import pathlib

    import numpy as np

    import labgains
    from labpkg.tuning import KD
    from labpkg import shapes

    pathlib.Path(__file__).with_name("IMPORTED").write_text("imported")


    class HelperPD:
        def __init__(self, model, *, Ts):
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


# --- Every way code reaches a run (issue 32, group 2) ---------------------------------

def _fingerprint(kind: str) -> str:
    """The fingerprint of a run of the law ``kind`` (nothing imported or built)."""
    config = json.loads(json.dumps(scenario_to_mapping(scenario_from_mapping(
        {"duration": 1.0, "transient": 0.5}))))
    return run_fingerprint({**config, "controller": {"kind": kind, "options": {}}})


def _install(site_dir, version: str, gain: str) -> None:
    """A plug-in distribution "labinst" as pip leaves it in site-packages: its module,
    its metadata and its RECORD (a hash per file)."""
    module = f"KP = {gain}\n\nclass PD:\n    def __init__(self, model, *, Ts):\n        pass\n"
    (site_dir / "labinst.py").write_text(module)
    info = site_dir / "labinst-0.dist-info"
    for old in site_dir.glob("labinst-*.dist-info"):
        for f in old.iterdir():
            f.unlink()
        old.rmdir()
    info = site_dir / f"labinst-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: labinst\nVersion: {version}\n")
    digest = hashlib.sha256(module.encode()).hexdigest()
    (info / "RECORD").write_text(f"labinst.py,sha256={digest},{len(module)}\n")
    (info / "top_level.txt").write_text("labinst\n")


def test_an_upgraded_installed_plugin_is_new_code(tmp_path, monkeypatch):
    site_dir = tmp_path / "site-packages"
    site_dir.mkdir()
    monkeypatch.syspath_prepend(str(site_dir))
    monkeypatch.setattr(site, "getsitepackages", lambda: [str(site_dir)])
    _install(site_dir, "1.0", "30.0")
    forget_plugins()
    try:
        assert plugin_sources("labinst:PD") == ()  # installed: not a user's file ...
        before = _fingerprint("labinst:PD")
        _install(site_dir, "1.1", "60.0")  # ... but its distribution is hashed
        forget_plugins()
        assert _fingerprint("labinst:PD") != before
    finally:
        forget_plugins()


def test_a_plugin_copied_into_site_packages_without_metadata_is_hashed(tmp_path, monkeypatch):
    """Known bad (issue 48, 14): a plug-in module put into site-packages by hand (no
    distribution declares it) entered the fingerprint as "undeclared" only: after an edit,
    resume reused the old results.  Now its source is hashed like the user's own."""
    site_dir = tmp_path / "site-packages"
    site_dir.mkdir()
    monkeypatch.syspath_prepend(str(site_dir))
    monkeypatch.setattr(site, "getsitepackages", lambda: [str(site_dir)])
    module = "KP = {}\n\nclass PD:\n    def __init__(self, model, *, Ts):\n        pass\n"
    (site_dir / "handcopied.py").write_text(module.format(30.0))
    forget_plugins()
    try:
        assert plugin_sources("handcopied:PD") == (site_dir / "handcopied.py",)
        before = _fingerprint("handcopied:PD")
        (site_dir / "handcopied.py").write_text(module.format(60.0))
        forget_plugins()
        assert _fingerprint("handcopied:PD") != before
    finally:
        forget_plugins()


def test_a_plugin_inside_a_project_package_is_hashed(plugin_lab):
    plugin_lab({})  # fresh caches
    inside = _ROOT / "controllers" / "zz_lab_plugin.py"
    inside.write_text("class PD:\n    def __init__(self, model, *, Ts):\n        pass\n")
    try:
        forget_plugins()
        assert plugin_sources("controllers.zz_lab_plugin:PD") == (inside,)
        before = _fingerprint("controllers.zz_lab_plugin:PD")
        inside.write_text(inside.read_text() + "# edited\n")
        assert _fingerprint("controllers.zz_lab_plugin:PD") != before
    finally:
        inside.unlink()
        forget_plugins()


def test_a_sourceless_plugin_and_what_its_bytecode_imports_are_hashed(plugin_lab):
    lab = plugin_lab({"labdeep.py": "KP = 30.0\n",
                      "labpyc.py": "def helper():\n    from labdeep import KP\n    return KP\n",
                      "lablaw2.py": "import labpyc\n\nclass PD:\n"
                                    "    def __init__(self, model, *, Ts):\n        pass\n"})
    py_compile.compile(str(lab / "labpyc.py"), cfile=str(lab / "labpyc.pyc"))
    (lab / "labpyc.py").unlink()  # shipped as bytecode only
    files = {p.name for p in plugin_sources("lablaw2:PD")}
    assert files == {"lablaw2.py", "labpyc.pyc", "labdeep.py"}  # its lazy import followed
    before = _fingerprint("lablaw2:PD")
    (lab / "labdeep.py").write_text("KP = 60.0\n")
    assert _fingerprint("lablaw2:PD") != before


def test_an_edit_of_the_views_intrinsics_rekeys_every_kernel_that_uses_them(monkeypatch):
    """reduced_model/dynamics/linalg.py defines numba intrinsics (`matrix_view`) beside
    its @njit functions: the kernels that inline them must be recompiled when it changes
    (it was not guarded)."""
    before = kernel_keys()
    assert "reduced_model/dynamics/linalg.py" in before
    views = _ROOT / "reduced_model" / "dynamics" / "linalg.py"
    original = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes",
                        lambda self: original(self) + (b"#" if self == views else b""))
    after = kernel_keys()
    changed = {k for k in before if before[k] != after[k]}
    assert {"reduced_model/dynamics/linalg.py", "reduced_model/dynamics/motion.py",
            "reduced_model/plant/plant.py", "controllers/_pbc.py", "controllers/_ekf.py"} <= changed
    assert "controllers/_replay.py" not in changed  # what does not use them keeps its cache


KERNEL_LAW = textwrap.dedent('''
    from numba import njit

    from labkern import gain


    @njit(cache=True)
    def torque(x):
        return gain() * x


    class PD:
        def __init__(self, model, *, Ts):
            pass
''')
PROBE = textwrap.dedent('''
    import sys
    if sys.argv[1] == "resolve":  # as every run does: through the registry
        from controllers import CONTROLLERS, resolve
        resolve("labkernlaw:PD", CONTROLLERS, "controller")
    import labkernlaw
    print(labkernlaw.torque(1.0))
''')


@pytest.mark.parametrize("cache_dir", [False, True], ids=["pycache", "NUMBA_CACHE_DIR"])
def test_a_compiled_plugin_never_runs_its_helpers_old_code(tmp_path, cache_dir):
    """A plug-in's cached kernel inlines its helper from another module: numba keys the
    cache on the kernel's own file, so after the helper changes the cache holds the old
    code (shown through a plain import) — the registry deletes it first."""
    lab = write_files(tmp_path / "lab", {
        "labkernlaw.py": KERNEL_LAW, "probe.py": PROBE,
        "labkern.py": "from numba import njit\n\n@njit(cache=True)\ndef gain():\n    return 2.0\n"})
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = f"{lab}:{_ROOT}"
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")

    def probe(how):
        proc = subprocess.run([sys.executable, "probe.py", how], cwd=lab, env=env,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        return float(proc.stdout.split()[-1])

    assert probe("resolve") == 2.0  # compiled and cached
    (lab / "labkern.py").write_text((lab / "labkern.py").read_text().replace("2.0", "3.0"))
    assert probe("import") == 2.0  # known-bad: numba alone reuses the stale machine code
    assert probe("resolve") == 3.0  # the guard deleted it: the edited helper runs
    cached = (tmp_path / "numba-cache") if cache_dir else (lab / "__pycache__")
    assert list(cached.rglob("labkernlaw.*.nbi"))  # the caches are where we looked


ZIP_LAW = textwrap.dedent('''
    class ZipPD:
        """A PD law shipped in a zip archive."""
        def __init__(self, model, *, Ts):
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
