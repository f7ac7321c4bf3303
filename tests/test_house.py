"""The structure of the code: the fingerprint covers everything a run loads, each setting
belongs to what it sets, every command reads a file the same way, and the rooms of
`validation` import each other in one direction only."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from reduced_model.code import imports
from validation.batch import compiling
from validation.batch.fingerprint import (_ROOT, code_fingerprint, plugin_sources,
                                          result_sources, run_fingerprint)
from validation.batch.store.folder import run_id
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping

HELPER = "GAIN = 30.0\n"
PLUGIN = textwrap.dedent('''
    import numpy as np
    from houselab.helpers import GAIN


    class PD:
        def __init__(self, model, *, Ts):
            pass

        def __call__(self, t, x, ref):
            n = x.shape[0] // 2
            theta_d, dtheta_d, _ = ref(t)
            return GAIN * (theta_d - x[:2]) + 10.0 * (dtheta_d - x[n:n + 2])
''')


@pytest.fixture
def plugin_package(plugin_lab):
    """A plug-in package with a helper module, importable from its folder."""
    return plugin_lab({"houselab/__init__.py": "", "houselab/helpers.py": HELPER,
                       "houselab/control.py": PLUGIN}) / "houselab"


PLANT = textwrap.dedent('''
    from reduced_model import ReducedPlant


    class Fine(ReducedPlant):
        """The reduced plant as a plug-in."""
''')
HIDDEN = textwrap.dedent('''
    import importlib

    from houselab.control import PD


    class Hidden(PD):
        def __init__(self, model, *, Ts):
            super().__init__(model, Ts=Ts)
            importlib.import_module("houselab." + "helpers_by_name")
''')
#: Runs of every kind a run can load different code for: a plug-in law on both plants, the
#: exact kinematics, the lab arm's joint effects, a plug-in plant, an arm of one and of
#: three links, an arm in gravity.
RUNS = [
    {"plant": {"kind": "reduced"}, "controller": {"kind": "houselab.control:PD"},
     "observer": {"kind": "smo-paper"}},
    {"plant": {"kind": "exudyn"}, "controller": {"kind": "houselab.control:PD"},
     "observer": {"kind": "smo-paper"}},
    {"plant": {"kind": "reduced", "kinematics": "exact"}, "arm": "lab",
     "controller": {"kind": "pd"}, "observer": {"kind": "ekf-pos"}},
    {"plant": {"kind": "exudyn"}, "arm": "lab"},
    {"plant": {"kind": "houselab.plant:Fine", "role": "reduced"}},
    {"arm": "single-link", "observer": {"kind": "none"}},
    {"arm": "three-link", "observer": {"kind": "none"}},
    {"arm": "vertical-two-link", "observer": {"kind": "none"}},
]
LOADED = textwrap.dedent('''
    import json, sys
    from validation.batch.worker import execute_run
    for config in json.loads(sys.argv[1]):
        result, _ = execute_run({"duration": 0.01, "transient": 0.0, **config})
        assert result.status == "ok", (config, result.message)
    print(json.dumps(sorted(m.__file__ for m in list(sys.modules.values())
                            if getattr(m, "__file__", None))))
''')


def _loaded(folder: Path, runs: list[dict]) -> set[Path]:
    """Every file a fresh process (the worker's path) loads to execute ``runs``."""
    proc = subprocess.run([sys.executable, "-c", LOADED, json.dumps(runs)], capture_output=True,
                          text=True, cwd=folder, timeout=900,
                          env={**os.environ, "PYTHONPATH": f"{folder}:{_ROOT}"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {Path(f).resolve() for f in json.loads(proc.stdout.splitlines()[-1])}


def test_the_fingerprint_covers_every_project_module_a_run_loads(plugin_package):
    """Execute a run of every kind (`RUNS`) in a fresh process, collect every module it
    loaded — found by what the process imported, not by a list: each project file is hashed
    into the code fingerprint, each plug-in file into its run's fingerprint; the command
    line, the store and the reports stay out (editing them leaves stored runs valid)."""
    (plugin_package / "plant.py").write_text(PLANT)
    loaded = _loaded(plugin_package.parent, RUNS)
    packages = [_ROOT / name for name in ("reduced_model", "plant_exudyn", "controllers",
                                          "validation")]
    project = {p for p in loaded if any(p.is_relative_to(d) for d in packages)}
    assert project, "nothing of the project was loaded?"
    hashed = set(result_sources())
    assert project <= hashed, sorted(str(p) for p in project - hashed)
    for kind in ("exact", "joints", "plant_exudyn"):  # the kernels a string registry hid
        assert any(kind in str(p) for p in project), kind
    plugin = {p for p in loaded if p.is_relative_to(plugin_package)}
    kinds = ("houselab.control:PD", "houselab.plant:Fine")
    assert plugin == {f for kind in kinds for f in plugin_sources(kind)} == {
        plugin_package / name for name in ("__init__.py", "helpers.py", "control.py",
                                           "plant.py")}
    for name in ("validation/cli/one_run.py", "validation/batch/store/folder.py",
                 "validation/report/report.py", "validation/verdicts/claims.py",
                 "validation/run/plotting.py"):
        assert _ROOT / name not in hashed, name


def test_a_module_imported_by_a_string_is_caught(plugin_package):
    """Known-bad of the test above (issue 55): a module imported by a string built at run
    time (the kernels' old registry) is loaded but not found by the static walk — the
    comparison of what a process loaded with what is hashed flags it."""
    (plugin_package / "helpers_by_name.py").write_text("VALUE = 1\n")
    (plugin_package / "hidden.py").write_text(HIDDEN)
    loaded = _loaded(plugin_package.parent, [{"controller": {"kind": "houselab.hidden:Hidden"},
                                             "observer": {"kind": "none"}}])
    plugin = {p for p in loaded if p.is_relative_to(plugin_package)}
    missed = plugin - set(plugin_sources("houselab.hidden:Hidden"))
    assert missed == {plugin_package / "helpers_by_name.py"}


def test_editing_a_hashed_file_changes_the_fingerprint(plugin_package, monkeypatch):
    """The hash covers each file's content: editing any one changes it (simulated by
    reading one file with a byte appended)."""
    config = scenario_to_mapping(scenario_from_mapping(
        {"controller": {"kind": "houselab.control:PD"}}))
    before = run_fingerprint(config)
    files = [*result_sources()[::7], *plugin_sources("houselab.control:PD")]
    original = Path.read_bytes
    for edited in files:
        monkeypatch.setattr(Path, "read_bytes", lambda self, e=edited: original(self) + (
            b"#" if self == e else b""))
        code_fingerprint.cache_clear()
        assert run_fingerprint(config) != before, edited
    monkeypatch.setattr(Path, "read_bytes", original)
    code_fingerprint.cache_clear()
    assert run_fingerprint(config) == before


def test_reading_a_plugins_fingerprint_imports_nothing(plugin_package):
    """Stored runs are checked against the code without running a plug-in's module."""
    assert "houselab" not in sys.modules and "houselab.control" not in sys.modules
    run_fingerprint({"controller": {"kind": "houselab.control:PD"}})
    assert "houselab" not in sys.modules and "houselab.control" not in sys.modules


@pytest.mark.parametrize("a, b", [
    ({"plant": {"kind": "exudyn"}},
     {"plant": {"kind": "exudyn", "mesh": {"element": "ancf"}, "spectral_radius": 0.9}}),
    ({"disturbances": [{"kind": "pulse", "amplitude": 1.0}]},
     {"disturbances": [{"kind": "pulse", "amplitude": 1.0, "duration": 0.1}]}),
    ({"sensors": {"modal": "gauges"}},
     {"sensors": {"modal": "gauges", "strain_quantity": "curvature"}}),
])
def test_equal_scenarios_have_equal_run_ids(a, b):
    """Defaults written out or left out: the same run, the same id."""
    ma = scenario_to_mapping(scenario_from_mapping(a))
    mb = scenario_to_mapping(scenario_from_mapping(b))
    assert ma == mb and run_id(ma) == run_id(mb)


def test_every_command_reads_a_scenario_file_the_same_way(tmp_path, monkeypatch):
    """run, stability and attribute accept the same scenario file (with a ``name``, the
    case that once drifted) and hand the same scenario to their work."""
    from validation import cli
    from validation.cli import verdicts as verdict_commands
    from validation.verdicts import attribution
    path = tmp_path / "s.toml"
    path.write_text('name = "mine"\nduration = 0.5\ntransient = 0.1\n'
                    '[controller]\nkind = "pd"\n')
    seen = {}

    class Stop(Exception):
        pass

    def record(command):
        def fake(first, *args, **kwargs):
            scenarios = first if isinstance(first, list) else [first]
            seen[command] = [scenario_to_mapping(getattr(s, "scenario", s)) if not
                             isinstance(s, dict) else s for s in scenarios]
            raise Stop
        return fake

    monkeypatch.setattr(verdict_commands, "stability_map_into", lambda runner, scenarios, *a, **k:
                        record("stability")(list(scenarios)))
    monkeypatch.setattr(attribution, "attribute", record("attribute"))
    monkeypatch.chdir(tmp_path)
    for argv in (["run", "--config", str(path)], ["stability", str(path), "--workers", "1"],
                 ["attribute", str(path), "--factors", "sampling", "--workers", "1"]):
        # the scenarios compiled for are those the run's worker gets; the others compile
        # nothing here (their work is recorded instead)
        monkeypatch.setattr(compiling, "compile_for", record("run") if argv[0] == "run" else
                            lambda *a, **k: None)
        with pytest.raises(Stop):
            cli.main(argv)
    run, stab, att = seen["run"][0], seen["stability"][0], seen["attribute"][0]
    for key in ("duration", "controller", "plant", "true_params"):
        assert run[key] == stab[key] == att[key], key
    assert stab["name"] == att["name"] == "s/mine"


PACKAGES = ("validation", "reduced_model", "plant_exudyn", "controllers")


def _module_imports(path: Path, *, lazy: bool = False) -> set[str]:
    """The project's modules that ``path`` imports at module level (with ``lazy``, inside
    functions too)."""
    module = ".".join(path.relative_to(_ROOT).with_suffix("").parts).removesuffix(".__init__")
    out = set()
    for source, names in imports(path, module, nested=lazy):
        for full in (f"{source}.{name}" for name in names) if names else (source,):
            out.add(full if (_ROOT / Path(*full.split("."))).with_suffix(".py").exists()
                    else source)
    return {m for m in out if m.split(".")[0] in PACKAGES}


def _modules(*packages: str) -> dict[str, Path]:
    """Module name -> file of every module of ``packages`` (a package by its ``__init__``)."""
    return {".".join(p.relative_to(_ROOT).with_suffix("").parts).removesuffix(".__init__"): p
            for package in packages for p in (_ROOT / package).rglob("*.py")}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """An import cycle of ``graph`` (module -> the modules it imports), or None."""
    state: dict[str, int] = {}

    def visit(m, path):
        if state.get(m) == 1:
            return [*path[path.index(m):], m]
        if state.get(m) == 2:
            return None
        state[m] = 1
        for d in sorted(graph[m]):
            found = visit(d, [*path, m])
            if found:
                return found
        state[m] = 2
        return None

    return next((c for m in sorted(graph) if (c := visit(m, []))), None)


def test_the_project_has_no_import_cycle():
    """No cycle among the project's modules, imports inside functions included (issue 44:
    campaign <-> queue and metrics -> results -> plotting -> metrics were cycles through
    imports inside functions).  Known bad: the cycle of a module importing its importer
    is found."""
    modules = _modules(*PACKAGES)
    graph = {m: _module_imports(p, lazy=True) & set(modules) for m, p in modules.items()}
    found = _cycle(graph)
    assert found is None, "import cycle: " + " -> ".join(found)
    bad = dict(graph)
    bad["validation.run.vibration"] = graph["validation.run.vibration"] | {
        "validation.run.metrics"}
    assert _cycle(bad) is not None


ROOMS = ("run", "batch", "verdicts", "report")  # each builds only on the ones before it


def test_the_rooms_depend_in_one_direction():
    """run <- batch <- verdicts <- report (README, *Layout*), imports inside functions included;
    only the command line sits over every room."""
    for module, path in _modules("validation").items():
        if module.count(".") < 2:
            continue
        room = module.split(".")[1]
        if room not in ROOMS:
            continue
        for dep in _module_imports(path, lazy=True):
            if not dep.startswith("validation.") or dep.count(".") < 2:
                continue
            dep_room = dep.split(".")[1]
            assert dep_room in ROOMS and ROOMS.index(dep_room) <= ROOMS.index(room), \
                f"{module} ({room}) imports {dep} ({dep_room})"


def test_reading_results_never_loads_the_solver(tmp_path):
    """`export`, `report` and `show` read stored results: none of them imports Exudyn (its
    compiled module and OpenGL libraries), even for truth-plant runs.  Known bad: `run` on
    the truth plant does."""
    script = textwrap.dedent('''
        import sys
        from validation.cli import main
        status = main(sys.argv[1:])
        print("EXUDYN" if "exudyn" in sys.modules else "NO-EXUDYN")
        sys.exit(status)
    ''')
    out = tmp_path / "out"

    def flexarm(*args):
        return subprocess.run([sys.executable, "-c", script, *args], capture_output=True,
                              text=True, timeout=600, cwd=tmp_path)
    made = flexarm("run", "--plant", "exudyn", "--duration", "0.05", "--out", str(out))
    assert made.returncode == 0 and made.stdout.strip().endswith("EXUDYN"), made.stderr
    assert not made.stdout.strip().endswith("NO-EXUDYN")
    for args in (["export", str(out)], ["report", str(out)], ["show", str(out / "pbc@exudyn")]):
        proc = flexarm(*args)
        assert proc.returncode == 0, (args, proc.stderr)
        assert proc.stdout.strip().endswith("NO-EXUDYN"), (args, proc.stdout[-300:])


def test_importing_the_packages_does_no_io(tmp_path):
    """No import-time I/O of ours (issue 44, 5): importing the four packages hashes and
    records nothing — the numba cache check runs when the first model is built (numba
    itself makes its cache folders when a cached function is declared).  Known bad: the
    check ran at ``import reduced_model`` and wrote its record of keys there."""
    from reduced_model.code import KEYS_FILE
    cache = tmp_path / "numba-cache"
    script = textwrap.dedent('''
        import reduced_model, plant_exudyn, controllers, validation
        from reduced_model.code import fresh_kernel_caches
        print(fresh_kernel_caches.cache_info().currsize)
    ''')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    imported = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              env=env, timeout=300)
    assert imported.returncode == 0 and imported.stdout.strip() == "0", imported.stderr
    assert not list(cache.rglob(KEYS_FILE))
    built = subprocess.run([sys.executable, "-c", "import reduced_model\n"
                            "reduced_model.ArmModel()"], env=env, timeout=300)
    assert built.returncode == 0 and list(cache.rglob(KEYS_FILE))  # the first model checks


#: Modules still over the limit, each being split on its own branch (only shrinks).
OVERSIZED: set = set()


def test_no_module_is_over_500_lines():
    """One purpose per module (STYLE 13): none of the four packages' modules is over 500
    lines (issue 44: eight were)."""
    lengths = {str(p.relative_to(_ROOT)): len(p.read_text().splitlines())
               for package in PACKAGES for p in (_ROOT / package).rglob("*.py")}
    over = sorted(f"{m} ({n})" for m, n in lengths.items() if n > 500 and m not in OVERSIZED)
    assert not over, f"over 500 lines: {over}"
    done = sorted(m for m in OVERSIZED if lengths.get(m, 0) <= 500)
    assert not done, f"within 500 lines now, remove from OVERSIZED: {done}"


def _prefix_families(folder: Path) -> dict[str, list[str]]:
    """Name prefix (up to the first underscore) -> the modules of ``folder`` sharing it, for
    prefixes shared by three or more."""
    families: dict[str, list[str]] = {}
    for p in folder.glob("*.py"):
        if p.stem != "__init__":
            families.setdefault(p.stem.lstrip("_").split("_")[0], []).append(p.stem)
    return {k: sorted(v) for k, v in families.items() if len(v) >= 3}


def test_rooms_not_prefix_families(tmp_path):
    """A family of modules is a subpackage (issue 55: nine ``verdicts/calibration_*.py``):
    no folder of the four packages has three or more modules sharing a name prefix.  Known
    bad: a folder with ``calibration.py``, ``calibration_plan.py`` and ``_calibration_io.py``."""
    folders = {p.parent for package in PACKAGES for p in (_ROOT / package).rglob("*.py")}
    found = {str(f.relative_to(_ROOT)): fam for f in sorted(folders)
             if (fam := _prefix_families(f))}
    assert not found, found
    for name in ("calibration.py", "calibration_plan.py", "_calibration_io.py", "other.py"):
        (tmp_path / name).write_text("")
    assert _prefix_families(tmp_path) == {
        "calibration": ["_calibration_io", "calibration", "calibration_plan"]}


def _private_imports(module: str, path: Path) -> list[str]:
    """The private modules or names (``_name``) of another of the four packages that
    ``module`` (the file ``path``) imports, inside functions too."""
    top, out = module.split(".")[0], []
    for source, names in imports(path, module, nested=True):
        parts = source.split(".")
        if parts[0] in PACKAGES and parts[0] != top and any(
                p.startswith("_") and not p.startswith("__") for p in [*parts[1:], *names]):
            out.append(f"{module}: from {source} import {', '.join(names)}")
    return out


def test_no_package_imports_another_packages_private_code(tmp_path):
    """A package's private modules and names are its own (issue 55: 26 imports such as
    ``from reduced_model._kernels import ...``): the public face of each package is what
    the others use.  Known bad: a module of `controllers` importing a private module and a
    private name of `reduced_model`."""
    found = [line for module, path in _modules(*PACKAGES).items()
             for line in _private_imports(module, path)]
    assert not found, found
    bad = tmp_path / "bad.py"
    bad.write_text("from reduced_model._kernels import step\n"
                   "def f():\n    from reduced_model.model import _packed\n")
    assert len(_private_imports("controllers.bad", bad)) == 2
