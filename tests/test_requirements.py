"""Requirements and their robustness ρ: claims give ρ = bound − value, STL formulas
RTAMT's robustness; every stored run carries ``rho_<name>``; bad requirements are
refused before anything runs."""
import dataclasses
import math

import numpy as np
import pytest

from cli_testing import flexarm
from validation.batch.store.folder import ResultStore
from validation.batch.worker import execute_run
from validation.run.config import ConfigError
from validation.run.claim_measures import claim_by_key
from validation.run.loop import run_scenario
from validation.run.metrics import all_metrics
from validation.run.requirements import Requirement, robustness
from validation.run.results import RunResult
from validation.run.scenario import scenario_from_mapping


@pytest.fixture(scope="module")
def paper_run():
    """The PBC with the true state, moving with the reference: 3 s on the reduced plant."""
    return run_scenario(scenario_from_mapping({"duration": 3.0, "transient": 1.0,
                                               "initial_state": "reference"}))


def replaced(result: RunResult, **signals) -> RunResult:
    out = result.signals.astype(float).copy()
    for name, values in signals.items():
        out[result.names.index(name)] = values
    return dataclasses.replace(result, signals=out)


def rho(requirement: Requirement, result: RunResult) -> float:
    return robustness(requirement, result, all_metrics(result))[0]


def test_a_perfect_tracker_has_rho_equal_to_the_bound_and_an_idle_one_negative(paper_run):
    r = paper_run
    perfect = replaced(r, theta1=r["theta1_ref"], theta2=r["theta2_ref"])
    zero = np.zeros_like(r.time)
    idle = replaced(r, theta1=zero, theta2=zero)
    req = Requirement(name="track", claim="tracking")
    bound = claim_by_key("tracking").bound
    # The perfect tracker's error is exactly 0: ρ = bound − 0, exactly.
    assert rho(req, perfect) == bound
    assert rho(req, idle) < 0
    # The same requirement as a formula: the claim measures after the 1 s transient.
    stl = Requirement(name="track_stl",
                      formula="always[1,3](abs(theta1 - theta1_ref) <= 0.02 and "
                              "abs(theta2 - theta2_ref) <= 0.02)")
    assert rho(stl, perfect) == pytest.approx(bound, abs=1e-15)
    assert rho(stl, idle) < 0
    # On the real run both measure the same worst error after the transient (float64
    # signals, the same samples): equal to rounding.
    assert rho(stl, r) == pytest.approx(rho(req, r), abs=1e-15)


def synthetic(theta1, ref, Ts=1e-3) -> RunResult:
    n = len(theta1)
    return RunResult(time=np.arange(n) * Ts, names=("theta1", "theta1_ref"),
                     signals=np.array([theta1, ref], float), config={"Ts": Ts})


def stl(formula: str, run: RunResult) -> float:
    return robustness(Requirement(name="r", formula=formula), run, {})[0]


def test_an_stl_formula_has_the_hand_computed_robustness():
    #       t [ms]  0     1      2      3      4     5      6     7      8      9
    error = np.array([0.0, 0.05, 0.004, -0.012, 0.003, 0.0, -0.007, 0.1, 0.015, 0.002])
    ref = np.linspace(0.0, 1.0, error.size)
    run = synthetic(ref + error, ref)
    # always over samples 2..5: 0.02 − max |e| there = 0.02 − 0.012
    assert stl("always[0.002,0.005](abs(theta1 - theta1_ref) <= 0.02)", run) == \
        pytest.approx(0.008, abs=1e-15)
    # eventually over samples 6..8 of (e >= 0.01): max(e − 0.01) = 0.1 − 0.01
    assert stl("eventually[0.006,0.008](theta1 - theta1_ref >= 0.01)", run) == \
        pytest.approx(0.09, abs=1e-15)
    # a window past the end sees only samples 8 and 9: 0.02 − 0.015
    assert stl("always[0.008,0.02](abs(theta1 - theta1_ref) <= 0.02)", run) == \
        pytest.approx(0.005, abs=1e-15)
    # and of two: the minimum (0.008 from the first; the second conjunct gives 0.02 − 0.1)
    assert stl("always[0.002,0.005](abs(theta1 - theta1_ref) <= 0.02) and "
               "always[0,0.009](abs(theta1 - theta1_ref) <= 0.02)", run) == \
        pytest.approx(0.02 - 0.1, abs=1e-15)


def test_the_sliding_window_monitor_equals_rtamts_own():
    """The O(n) windows give exactly RTAMT's own O(n·w) values (random signals, nested
    future and past operators, windows past either end of the trace)."""
    import rtamt

    from validation.run.requirements import _parse
    rng = np.random.default_rng(3)
    n, Ts = 400, 1e-3
    formulas = ["always[0,0.05](a <= 0.5)", "eventually[0.01,0.02](a >= b)",
                "historically[0,0.03](abs(a - b) < 1)", "once[0.002,0.04](a > 0)",
                "always[0.01,0.5](eventually[0,0.02](a >= 0.3) or b < -1)",
                "always(a <= 2) and eventually[0.1,0.2](b > 0)", "always[0.1,0.1](a > -5)",
                "once[0,0.5](a > 0) -> historically[0.001,0.002](b < 1)"]
    for formula in formulas:
        reference = rtamt.StlDiscreteTimeOfflineSpecification()
        for v in ("a", "b"):
            reference.declare_var(v, "float")
        reference.spec = formula
        reference.set_sampling_period(1_000_000, "ns", 0.1)
        reference.parse()
        ours, _ = _parse(formula, ("a", "b"), Ts)
        for _ in range(3):
            data = {"time": (np.arange(n) * Ts).tolist(), "a": rng.normal(size=n).tolist(),
                    "b": rng.normal(size=n).tolist()}
            expected = [v for _, v in reference.evaluate(dict(data))]
            assert [v for _, v in ours.evaluate(dict(data))] == expected, formula


@pytest.mark.parametrize("entry, path, words", [
    ({"name": "x", "formula": "always[0,1](theta1 <= "}, "requirement[0].formula",
     "does not parse"),
    ({"name": "x", "formula": "always(thetta1 <= 0.1)"}, "requirement[0].formula",
     "unknown signal 'thetta1'"),
    ({"name": "x", "formula": "always[0,0.0015](theta1 <= 0.1)"}, "requirement[0].formula",
     "multiple of the sampling period"),
    ({"name": "x", "claim": "trackin"}, "requirement[0].claim", "unknown claim 'trackin'"),
    ({"name": "x", "claim": "tracking", "formula": "theta1 <= 1"}, "requirement[0].name",
     "exactly one"),
    ({"name": "x/y", "claim": "tracking"}, "requirement[0].name", "plain name"),
])
def test_a_bad_requirement_is_refused_naming_its_key(entry, path, words):
    with pytest.raises(ConfigError) as info:
        scenario_from_mapping({"duration": 3.0, "requirement": [entry]})
    assert info.value.path == path
    assert words in info.value.message


def test_estimates_are_signals_only_with_an_observer():
    with pytest.raises(ConfigError, match="unknown signal 'xhat_theta1'"):
        scenario_from_mapping({"requirement": [{"name": "e", "formula":
                                                "always(abs(xhat_theta1 - theta1) < 0.1)"}]})
    scenario_from_mapping({"observer": {"kind": "smo-bl"}, "requirement": [
        {"name": "e", "formula": "always(abs(xhat_theta1 - theta1) < 0.1)"}]})


def test_every_stored_run_carries_its_requirements_robustness(tmp_path):
    scenario = scenario_from_mapping({
        "duration": 3.0, "transient": 1.0, "requirement": [
            {"name": "track", "claim": "tracking"},
            {"name": "early", "formula": "eventually[0,1](theta1 <= 0)"}]})
    result, metrics = execute_run(scenario)
    assert metrics["rho_track"] == pytest.approx(
        0.02 - max(metrics["track_max_1"], metrics["track_max_2"]), abs=1e-15)
    # A window beyond the run is refused (issue 48, 16; the evaluator's own semantics of
    # one, ±∞, is tested in tests/reliability/test_verdicts.py); the store keeps ±∞.
    with pytest.raises(ConfigError, match=r"requirement\[0\]\.formula: .*reaches beyond"):
        scenario_from_mapping({"duration": 3.0, "requirement": [
            {"name": "vacuous", "formula": "always[10,20](theta1 <= 0)"}]})
    metrics |= {"rho_vacuous": math.inf, "rho_never": -math.inf}
    store = ResultStore(tmp_path)
    store.add("0123456789ab", result, metrics)
    row = store.row("0123456789ab")
    assert row.metrics["rho_vacuous"] == math.inf and row.metrics["rho_never"] == -math.inf
    assert row.metrics["rho_track"] == metrics["rho_track"]


def test_the_cli_refuses_an_unknown_signal_in_one_line_writing_nothing(tmp_path):
    config = tmp_path / "s.toml"
    config.write_text('duration = 3.0\n[[requirement]]\nname = "r"\n'
                      'formula = "always(abs(tau3) <= 1)"\n')
    out = tmp_path / "out"
    done = flexarm(None, "run", "--config", config, "--out", out)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "requirement[0].formula" in done.stderr
    assert "'tau3'" in done.stderr
    assert not out.exists()


def test_requirements_enter_the_claims_table():
    from types import SimpleNamespace

    from validation.report.verdict_tables import claims_tables
    from validation.verdicts.claims import claim_columns
    scenario = scenario_from_mapping({
        "name": "paper/pbc+smo-paper", "duration": 3.0, "transient": 1.0,
        "observer": {"kind": "smo-paper"},
        "requirement": [{"name": "loose", "formula": "always[1,3](abs(theta1 - theta1_ref) "
                                                     "<= 0.5)"},
                        {"name": "tight", "formula": "always[1,3](abs(theta1 - theta1_ref) "
                                                     "<= 1e-6)"}]})
    result, metrics = execute_run(scenario)
    run = SimpleNamespace(name=scenario.name, config=result.config, status=result.status,
                          message="", end_time=result.end_time, metrics=metrics,
                          load=lambda: result, run_id="x")
    (table,) = claims_tables(claim_columns([run]))
    rows = {row["key"]: row for row in table["rows"]}
    assert rows["rho_loose"]["verdicts"] == ["holds"]
    assert rows["rho_tight"]["verdicts"] == ["fails"]
    assert rows["rho_loose"]["cells"][0] == \
        f"ρ = {metrics['rho_loose']:.4g} (in the signals' units) — holds"
    assert rows["rho_loose"]["claim"] == \
        "requirement loose: always[1,3](abs(theta1 - theta1_ref) <= 0.5)"


def test_a_campaign_files_requirements_apply_to_every_run(tmp_path):
    """Top-level [[requirement]] entries of a campaign join each run's own; a scenario
    file with [[requirement]], [uncertainty] and [verify] stays a scenario file."""
    from validation.batch.campaign import campaign_from_mapping, expand, load_study
    campaign = campaign_from_mapping({
        "name": "c", "requirement": [{"name": "b", "claim": "vibration"}],
        "scenario": {"duration": 3.0, "requirement": [{"name": "a", "claim": "tracking"}]},
        "sweep": [{"name": "s", "grid": {"true_params": {"Mp": [0.1, 0.2]}}}]})
    runs = expand(campaign)
    assert [[r.name for r in run.scenario.requirement] for run in runs] == [["a", "b"]] * 2
    path = tmp_path / "s.toml"
    path.write_text('duration = 3.0\n[[requirement]]\nname = "a"\nclaim = "tracking"\n'
                    '[uncertainty]\n"true_params.Mp" = { uniform = [0.0, 1.0] }\n'
                    '[verify]\nlevel = 0.9\n')
    study = load_study(path)
    assert study.uncertainty and study.verify == {"level": 0.9}
    (run,) = expand(study)
    assert [r.name for r in run.scenario.requirement] == ["a"]


def test_rho_is_said_with_its_unit():
    """ρ = bound − value is in the claim's unit (a formula's: its signals'); never a bare
    17-digit number."""
    claim = Requirement(name="track", claim="tracking")
    assert claim.rho_text(0.006922997845848383) == "0.006923 rad"
    assert claim.rho_text(-math.inf) == "−inf (diverged)"
    assert claim.rho_text(None) == "— (no run)"
    stl = Requirement(name="f", formula="always(abs(theta1) <= 3)")
    assert stl.rho_text(1.5) == "1.5 (in the signals' units)"
