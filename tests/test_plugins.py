"""Bring your own controller and observer: plug-ins defined outside the package run
everywhere the built-ins run, and their failures are results or one-line errors."""
import json
import textwrap

import pytest

from cli_testing import flexarm
from validation.batch.worker import execute_run
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping
from validation.batch.store.folder import ResultStore

PLUGIN = textwrap.dedent('''
    """Plug-ins for the tests: written only against the public interface."""
    import numpy as np


    class MyPD:
        """Joint PD without feedforward, as a user would write it."""
        name = "my-pd"

        def __init__(self, model, *, Ts, kp=(30.0, 15.0), kd=(18.1, 8.2)):
            self.kp, self.kd = np.asarray(kp, float), np.asarray(kd, float)

        def __call__(self, t, x, ref):
            n = x.shape[0] // 2
            theta_d, dtheta_d, _ = ref(t)
            return self.kp * (theta_d - x[:2]) + self.kd * (dtheta_d - x[n:n + 2])


    class Boom(MyPD):
        """Raises at t = 0.5 s."""
        def __call__(self, t, x, ref):
            if t >= 0.5:
                raise RuntimeError("boom at half a second")
            return super().__call__(t, x, ref)


    class PassThrough:
        """An observer that returns the measured full state."""
        def __init__(self, model, *, Ts):
            self.measured = model.state_names

        def reset(self, x_hat0):
            self.x = np.array(x_hat0, float)
            return self.x.copy()

        def update(self, t, y, tau):
            self.x = np.array(y, float)
            return self.x.copy()


    class Periodless:
        """Known-bad: a law that does not take the control period."""

        def __init__(self, model, *, kp=1.0):
            self.kp = kp

        def __call__(self, t, x, ref):
            return self.kp * (ref(t)[0] - x[:2])


    class NoUpdate:
        measured = ("theta1",)

        def __init__(self, model, *, Ts):
            pass

        def reset(self, x_hat0):
            return x_hat0
''')


@pytest.fixture()
def plugin_dir(plugin_lab):
    return plugin_lab({"mylab_plugins.py": PLUGIN})


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
def test_a_plugin_reproduces_the_builtin_pd(plugin_dir, plant):
    base = {"duration": 3.0, "plant": {"kind": plant}}
    builtin = execute_run(scenario_to_mapping(scenario_from_mapping(
        base | {"controller": {"kind": "pd", "options": {"feedforward": False}}})))[1]
    plugin = execute_run(scenario_to_mapping(scenario_from_mapping(
        base | {"controller": {"kind": "mylab_plugins:MyPD"}})))[1]
    keys = [k for k, v in builtin.items() if isinstance(v, float)]
    assert len(keys) > 20
    for k in keys:  # the same arithmetic in another order: agreement to 1e-9
        # NaN on both (a metric the 3 s run is too short for, e.g. vib_decay) agrees.
        assert plugin[k] == pytest.approx(builtin[k], rel=1e-9, abs=1e-12, nan_ok=True), k


def test_flexarm_run_and_a_two_worker_campaign_with_plugins(plugin_dir):
    out = plugin_dir / "run"
    proc = flexarm(plugin_dir, "run", "--controller", "mylab_plugins:MyPD", "--observer",
                   "mylab_plugins:PassThrough", "--duration", "3", "--plant", "exudyn",
                   "--set", "controller.options.kp=[20.0, 10.0]", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    (row,) = ResultStore(out).rows()
    assert row.status == "ok" and row.config["controller"]["options"]["kp"] == [20.0, 10.0]
    camp = plugin_dir / "c.toml"
    camp.write_text('name = "plug"\n[scenario]\nduration = 1.0\ntransient = 0.5\n'
                    'controller.kind = "mylab_plugins:MyPD"\n'
                    '[[sweep]]\ngrid.plant.kind = ["reduced", "exudyn"]\n'
                    'zip.name = ["fine", "boom"]\n'
                    'zip.controller.kind = ["mylab_plugins:MyPD", "mylab_plugins:Boom"]\n')
    proc = flexarm(plugin_dir, "campaign", str(camp), "--out", str(plugin_dir / "c"),
                   "--workers", "2", "--no-progress")
    # The raising plug-in fails its two runs (exit 1); the campaign completes the others.
    assert proc.returncode == 1, proc.stderr
    rows = {(r.name, r.plant): r for r in ResultStore(plugin_dir / "c").rows()}
    assert len(rows) == 4
    for plant in ("reduced", "exudyn"):
        assert rows[("plug/fine", plant)].status == "ok"
        boom = rows[("plug/boom", plant)]
        assert boom.status == "failed"
        assert "raised RuntimeError: boom at half a second at t = 0.5 s" in boom.message


@pytest.mark.parametrize("args, key", [
    (["--controller", "nosuchmodule:Law"], "controller.kind: cannot import 'nosuchmodule'"),
    (["--controller", "mylab_plugins:Nothing"], "controller.kind: module 'mylab_plugins' has no"),
    (["--controller", "mylab_plugins:MyPD", "--set", "controller.options.kq=1.0"],
     "controller.options.kq: not an option of mylab_plugins:MyPD"),
    (["--observer", "mylab_plugins:NoUpdate"], "observer.kind: mylab_plugins:NoUpdate has no "
                                              "method update()"),
    (["--controller", "pbc", "--set", "controller.options.kv_flex=5.0"],
     "controller.options.kv_flex: not an option of pbc"),
    (["--observer", "mylab_plugins:PassThrough", "--set", "sensors.rates=false"],
     "observer.kind: mylab_plugins:PassThrough needs the measurements"),
    # The control period is set once, when a law is built: never an option, always taken.
    (["--controller", "mylab_plugins:Periodless"],
     "controller.kind: mylab_plugins:Periodless does not take the control period"),
    (["--controller", "lqr", "--set", "controller.options.Ts=2e-3"],
     "controller.options.Ts: the control period is the scenario's Ts"),
])
def test_bad_plugins_are_one_line_errors_and_nothing_is_written(plugin_dir, args, key):
    out = plugin_dir / "never"
    proc = flexarm(plugin_dir, "run", "--duration", "3", "--out", str(out), *args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error: " + key), proc.stderr
    assert not out.exists()


def test_the_realisable_pbc_refuses_its_dead_settings_with_the_reason():
    from validation.run.config import ConfigError
    with pytest.raises(ConfigError) as exc:
        scenario_from_mapping({"controller": {"kind": "pbc", "options": {"compensate_damping": False}}})
    assert exc.value.path == "controller.options.compensate_damping"
    assert "unactuated rows of eq. (20)" in exc.value.message
    # The idealised law takes them (they change its torque there).
    scenario_from_mapping({"controller": {"kind": "pbc-idealised",
                                          "options": {"compensate_damping": False}}})


def test_plugin_code_is_part_of_the_fingerprint(plugin_dir):
    """Editing a plug-in's module makes its stored runs stale (not reused)."""
    from validation.batch.fingerprint import forget_plugins, run_fingerprint
    config = json.loads(json.dumps(scenario_to_mapping(scenario_from_mapping(
        {"controller": {"kind": "mylab_plugins:MyPD"}}))))
    before = run_fingerprint(config)
    (plugin_dir / "mylab_plugins.py").write_text(PLUGIN + "\n# edited\n")
    forget_plugins()
    assert run_fingerprint(config) != before


@pytest.mark.parametrize("kind, role", [("lqr", "controller"), ("ekf", "observer"),
                                        ("smo-bl", "observer"), ("pbc", "controller")])
def test_a_law_is_built_at_the_scenarios_control_period(kind, role):
    """The period reaches a law one way, at construction (issue 44: it reached laws
    through constructor sniffing, ``update(..., Ts)`` and ``compiled(Ts)``, and the LQR's
    compiled form ignored its argument): a law built for Ts = 2 ms says so, and its
    compiled form takes no period of its own."""
    from validation.run.laws import build_controller, build_observer, nominal_model
    s = scenario_from_mapping({"Ts": 2e-3, role: {"kind": kind}})
    model = nominal_model(s.nominal_params, s.model.modes_per_link)
    law = (build_controller if role == "controller" else build_observer)(s, model)
    assert law.Ts == 2e-3
    assert law.compiled().pointer is not None  # compiled() takes no period


HELPERS = textwrap.dedent('''
    import numpy as np


    def gains(x):
        return np.linalg.cholesky(-np.eye(2)) @ x[:2]   # not positive definite: raises
''')
CONTROL = textwrap.dedent('''
    from tracelab.helpers import gains


    class Cholesky:
        def __init__(self, model, *, Ts):
            pass

        def __call__(self, t, x, ref):
            return gains(x)
''')


def line_of(text: str, needle: str) -> int:
    """The 1-based line of ``text`` holding ``needle`` (once)."""
    (number,) = [i + 1 for i, line in enumerate(text.splitlines()) if needle in line]
    return number


def test_a_raising_plugin_points_at_its_own_line(plugin_dir):
    """Issue 47: the message names the plug-in's file and line, the result carries its
    frames (the loop's own frames left out)."""
    from validation import run_scenario
    result = run_scenario(scenario_from_mapping(
        {"duration": 1.0, "controller": {"kind": "mylab_plugins:Boom"}}))
    line = line_of(PLUGIN, 'raise RuntimeError("boom at half a second")')
    assert result.status == "failed"
    assert result.message.endswith(f"(mylab_plugins.py:{line} in __call__)"), result.message
    assert f'mylab_plugins.py", line {line}, in __call__' in result.traceback
    assert 'raise RuntimeError("boom at half a second")' in result.traceback
    assert "validation" not in result.traceback  # the loop is not the author's code


def test_a_plugin_raising_in_a_library_points_at_its_helpers(plugin_lab):
    """Known-bad made visible: numpy raises inside the plug-in's helper module; the
    frames are the plug-in package's (control.py calling helpers.py), none of numpy's,
    and the location is the helper's line that called numpy."""
    from validation import run_scenario
    lab = plugin_lab({"tracelab/__init__.py": "", "tracelab/helpers.py": HELPERS,
                      "tracelab/control.py": CONTROL})
    result = run_scenario(scenario_from_mapping(
        {"duration": 0.01, "transient": 0.0, "controller": {"kind": "tracelab.control:Cholesky"}}))
    helper_line = line_of(HELPERS, "np.linalg.cholesky")
    assert result.message.endswith(f"(tracelab/helpers.py:{helper_line} in gains)"), \
        result.message
    frames = result.traceback.splitlines()
    assert [f for f in frames if f.lstrip().startswith("File")] == [
        f'  File "{lab / "tracelab" / "control.py"}", line '
        f'{line_of(CONTROL, "return gains(x)")}, in __call__',
        f'  File "{lab / "tracelab" / "helpers.py"}", line {helper_line}, in gains']


def test_flexarm_run_and_show_print_where_a_plugin_raised(plugin_dir):
    """The frames are printed by ``flexarm run`` and stored with the run (``flexarm show``
    prints them from the folder); a failed run prints no metrics."""
    out = plugin_dir / "boom"
    line = line_of(PLUGIN, 'raise RuntimeError("boom at half a second")')
    proc = flexarm(plugin_dir, "run", "--controller", "mylab_plugins:Boom", "--duration", "1",
                   "--out", str(out))
    assert proc.returncode == 1, proc.stderr
    where = f'File "{plugin_dir / "mylab_plugins.py"}", line {line}, in __call__'
    # The failure is the command's error: on stderr, as show prints it (issue 58).
    assert where in proc.stderr and f"mylab_plugins.py:{line} in __call__" in proc.stderr
    assert "no metrics: the run failed after 0.5 of 1 s" in proc.stderr
    assert "max |θ1 − θ1d|" not in proc.stdout  # no table measured over 1 ms of a failure
    (row,) = ResultStore(out).rows()
    assert f"mylab_plugins.py:{line} in __call__" in row.message
    assert where in ResultStore(out).read(row.run_id)[0].traceback
    shown = flexarm(plugin_dir, "show", f"{out}/{row.run_id}", "--no-open")
    assert shown.returncode == 1 and where in shown.stderr, shown.stderr
