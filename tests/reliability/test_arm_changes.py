"""A changed arm changes the physics, not only the name (issue 59, item 1): wherever a
resolved scenario gets another ``arm`` (``run --like … --arm``, ``--set arm=`` on
``--like``, an uncertainty set's arm, a stability map's arms, a calibration experiment's
arm), its parameter tables follow the new arm and keep only the user's own values; a scale
axis that would give one arm another arm's value is refused."""
import pytest

from reduced_model import named_arm
from validation.batch.campaign import campaign_from_mapping, expand
from validation.batch.store.folder import ResultStore
from validation.cli import main
from validation.run.arms import parameter_value
from validation.run.config import ConfigError
from validation.run.scenario import own_parameters, scenario_from_mapping, scenario_to_mapping

SHORT = ["--duration", "0.2", "--name", "d"]


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """{arm: its stored row} of a plain ``flexarm run --arm ARM`` for the default and the
    lab arm (they differ in 18 joint parameters, in both tables)."""
    out = tmp_path_factory.mktemp("plain")
    rows = {}
    for arm in ("default", "lab"):
        assert main(["run", *SHORT, "--arm", arm, "--out", str(out / arm)]) == 0
        (rows[arm],) = ResultStore(out / arm).rows()
    return out, rows


@pytest.mark.parametrize("old, new", [("default", "lab"), ("lab", "default")])
def test_like_with_another_arm_is_that_arm(plain, tmp_path, capsys, old, new):
    """``--like RUN --arm NEW`` stores what a plain ``--arm NEW`` run stores: the same
    resolved scenario (hence the same run id), parameter tables and metrics.  Without
    the fix the tables and metrics stayed the old arm's (49.49 vs 52.95 mrad)."""
    out, rows = plain
    assert main(["run", "--like", f"{out / old}/d", "--arm", new, "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert f"arm = {new!r} (was {old!r})" in printed
    assert f"36 value(s) of true_params and nominal_params follow the {new} arm" in printed
    (again,) = ResultStore(tmp_path).rows()
    want = rows[new]
    assert again.config["arm"] == new
    for table in ("true_params", "nominal_params"):
        assert again.config[table] == want.config[table], table
        assert again.config[table] != rows[old].config[table], table  # the test can fail
    assert again.run_id == want.run_id
    assert again.metrics["track_max_1"] == pytest.approx(want.metrics["track_max_1"],
                                                         rel=1e-12)
    assert again.metrics["track_max_1"] != pytest.approx(
        rows[old].metrics["track_max_1"], rel=1e-3)  # the arms differ by 7 % here


def test_like_with_set_arm_keeps_the_users_own_values(plain, tmp_path, capsys):
    """``--set arm=…`` on ``--like`` is the same change; a value the stored run set itself
    (Mp) is kept over the new arm, one it took from its arm follows the new one."""
    out, rows = plain
    first = tmp_path / "heavy"
    assert main(["run", "--like", f"{out / 'default'}/d", "--set", "true_params.Mp=0.3",
                 "--out", str(first)]) == 0
    assert main(["run", "--like", f"{first}/d", "--set", 'arm="lab"',
                 "--out", str(tmp_path / "lab")]) == 0
    (row,) = ResultStore(tmp_path / "lab").rows()
    lab = named_arm("lab")
    assert row.config["true_params"] == scenario_to_mapping(lab.replace(Mp=0.3))
    assert row.config["nominal_params"] == scenario_to_mapping(lab)
    assert "true_params.Mp" not in capsys.readouterr().out.splitlines()[-1]


def test_own_parameters_are_the_values_that_differ_from_the_arm():
    s = scenario_from_mapping({"arm": "lab", "true_params": {"Mp": 0.3, "coulomb1": 0.35}})
    own = own_parameters(scenario_to_mapping(s))
    assert own["true_params"] == {"Mp": 0.3, "coulomb1": 0.35} and own["nominal_params"] == {}
    assert own["arm"] == "lab" and own["duration"] == s.duration


def test_a_sweep_scaling_an_arm_parameter_over_another_arm_is_refused():
    """``scale`` multiplies the base arm's value: 2 × the default arm's coulomb1 (0) would
    be the lab arm's coulomb1 (0.3 N m) without a word."""
    sweep = {"grid": {"arm": ["default", "lab"], "true_params": {"coulomb1": {"scale": [2]}}}}
    with pytest.raises(ConfigError, match=r"sweep\[0\].grid.true_params.coulomb1: scales "
                                          r"true_params.coulomb1 of the default arm \(0.0\), "
                                          r"but the axes also run the lab arm"):
        expand(campaign_from_mapping({"scenario": {"duration": 0.2}, "sweep": [sweep]}))
    random = {"random": {"samples": 2, "arm": {"choices": ["default", "lab"]},
                         "true_params.viscous1": {"scale": {"uniform": [1, 2]}}}}
    with pytest.raises(ConfigError, match=r"sweep\[0\].random.true_params.viscous1: scales"):
        expand(campaign_from_mapping({"scenario": {"duration": 0.2}, "sweep": [random]}))


def test_a_sweep_scaling_a_value_every_arm_shares_runs():
    """Mp is the same on both arms, coulomb1 is the base's own: both scale the same way
    on each arm, and each arm keeps its other joint values."""
    sweep = {"grid": {"arm": ["default", "lab"],
                      "true_params": {"Mp": {"scale": [2]}, "coulomb1": {"scale": [2]}}}}
    runs = expand(campaign_from_mapping({"scenario": {"duration": 0.2,
                                                      "true_params": {"coulomb1": 0.1}},
                                         "sweep": [sweep]}))
    by_arm = {r.scenario.arm: r.scenario.true_params for r in runs}
    assert {a: (p.Mp, p.coulomb1) for a, p in by_arm.items()} == {
        "default": (0.2, 0.2), "lab": (0.2, 0.2)}
    assert by_arm["lab"].gear_stiffness1 == 1e4 and by_arm["default"].gear_stiffness1 == 0


def test_an_uncertain_arm_is_that_arm():
    from validation.verdicts.uncertainty import System, _uncertainty
    nominal = scenario_to_mapping(scenario_from_mapping({"true_params": {"Mp": 0.3}}))
    system = System("s", nominal, _uncertainty({"arm": {"choices": ["default", "lab"]}},
                                               nominal, ""), None)
    s = system.scenario({"arm": "lab"})
    assert (s.true_params.coulomb1, s.true_params.Mp, s.nominal_params.coulomb1) == (0.3, 0.3,
                                                                                       0.3)
    with pytest.raises(ConfigError, match="uncertainty.true_params.coulomb1: scales"):
        _uncertainty({"arm": {"choices": ["default", "lab"]},
                      "true_params.coulomb1": {"scale": {"uniform": [1, 2]}}}, nominal, "")


def test_a_stability_map_on_another_arm_keeps_the_scenarios_own_values():
    from validation.verdicts.stability import cases_from_scenarios
    s = scenario_from_mapping({"true_params": {"Mp": 0.3}})
    cases = {c.arm: c.base for c in cases_from_scenarios([s], plants=["reduced"],
                                                         arms=["default", "lab"])}
    assert parameter_value(cases["lab"], "true_params.Mp") == 0.3
    assert parameter_value(cases["lab"], "true_params.coulomb1") == 0.3 == parameter_value(
        cases["lab"], "nominal_params.coulomb1")
    assert parameter_value(cases["default"], "true_params.coulomb1") == 0.0


def test_a_calibration_experiment_on_another_arm_is_that_arm():
    from types import SimpleNamespace
    from validation.verdicts.calibration.plan import _experiment_mapping
    base = scenario_to_mapping(scenario_from_mapping({"true_params": {"Mp": 0.3}}))
    data = _experiment_mapping(base, SimpleNamespace(name="e", duration=1.0), None,
                               {"arm": "lab"}, SimpleNamespace(names=()))
    s = scenario_from_mapping(data)
    assert (s.arm, s.true_params.coulomb1, s.true_params.Mp) == ("lab", 0.3, 0.3)
