"""The sampled-data stability map explains why the paper's own arm diverges at 1 ms."""
import math
from types import SimpleNamespace

from validation.report.verdict_tables import stability_rows
from validation.run.metrics import all_metrics
from validation.verdicts import stability
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping


def test_a_small_map_finds_the_table1_limit(tmp_path, monkeypatch):
    # Three control periods and no bisection keep this short (1 s runs).
    monkeypatch.setattr(stability, "GRID", (2e-4, 1e-3, 5e-3))
    monkeypatch.setattr(stability, "BISECTIONS", 0)
    monkeypatch.setattr(stability, "DURATION", 1.0)
    scenarios = [scenario_from_mapping({})]
    cases = stability.cases_from_scenarios(scenarios, plants=["reduced"],
                                           arms=["default", "table1"])
    results, summary = stability.stability_map(cases, tmp_path, progress=False)
    by_arm = {r.case.arm: r for r in results}
    assert summary.failed == 0
    # Table 1: stable at 0.2 ms, diverged at 1 ms (the review's finding, reproduced); both
    # limits are the same here, and nothing above them is good again.
    t1 = by_arm["table1"]
    assert t1.divergence.largest == 2e-4 and t1.divergence.first_bad == 1e-3
    assert t1.divergence.outcome == "diverged" and "exceeds" in t1.divergence.reason
    assert t1.tracking.largest == 2e-4 and t1.non_monotone == [] and t1.failed == []
    # The default arm (stator inertia) is stable at 1 ms; its limit lies below 5 ms.
    default = by_arm["default"]
    assert default.tracking.largest == 1e-3 and default.tracking.first_bad == 5e-3
    # The map can be rebuilt from the stored runs alone (what the report does).
    again = {r.case.arm: r for r in stability.load_stability(tmp_path)}
    assert again["table1"].tested == t1.tested


def _row(status: str, track: float = 0.01, message: str = "", metrics: dict | None = None):
    return SimpleNamespace(status=status, message=message,
                           metrics=metrics or {"track_max_1": track, "track_max_2": track / 2})


def test_lost_tracking_without_divergence_is_not_called_unstable():
    """The review's LQR case (Table 1, reduced plant): every run completes, the tracking
    error crosses 0.1 rad at 4.46 ms and is back under it at 10 ms.  The map reports no
    divergence up to 10 ms, tracking kept up to 3.98 ms, and the 10 ms run as a
    non-monotone case of the tracking limit."""
    rows = {1e-3: _row("ok", 0.03), 3.98e-3: _row("ok", 0.095), 4.46e-3: _row("ok", 0.101),
            5e-3: _row("ok", 0.12), 1e-2: _row("ok", 0.086)}
    tested = {Ts: stability.outcome(r) for Ts, r in rows.items()}
    assert tested[4.46e-3][0] == "lost tracking" and tested[1e-2][0] == "stable"
    case = stability.StabilityCase("lqr", "reduced", "table1",
                                   scenario_to_mapping(scenario_from_mapping({"arm": "table1"})))
    r = stability._result(case, tested)
    assert math.isnan(r.divergence.first_bad) and r.divergence.largest == 1e-2
    assert r.tracking.largest == 3.98e-3 and r.tracking.first_bad == 4.46e-3
    assert r.tracking.outcome == "lost tracking" and r.tracking.non_monotone == (1e-2,)
    assert r.non_monotone == ["kept tracking at 10 ms above the first lost tracking at 4.46 ms"]
    row = stability_rows([r])[0]
    assert row["no_divergence"] == "10" and row["first_divergence"] == "> 10"
    assert row["first_loss"] == "4.46 (lost tracking)" and "10 ms" in row["notes"]


def test_a_failed_run_is_failed_not_unstable():
    tested = {1e-3: stability.outcome(_row("ok")),
              2e-3: stability.outcome(_row("failed", message="Exudyn solver failed at t = 0.1 s")),
              5e-3: stability.outcome(_row("diverged", message="|θ̇| exceeds 100 rad/s"))}
    case = stability.StabilityCase("pbc", "exudyn", "default",
                                   scenario_to_mapping(scenario_from_mapping({})))
    r = stability._result(case, tested)
    # Nothing is known at 2 ms: both limits stop below it, and it is not a divergence.
    assert r.divergence.largest == 1e-3 and r.divergence.outcome == "failed"
    assert r.failed == [2e-3]
    assert "FAILED at 2 ms" in stability_rows([r])[0]["notes"]
    # A failure is not bisected towards: it says nothing about where a limit lies.
    assert stability._bisection_points(tested) == set()


def test_a_stability_campaign_with_a_solver_failure_exits_1(tmp_path, monkeypatch, capsys):
    """A Newton tolerance below ANCF's round-off makes Exudyn give up (as in the
    reliability suite) where the limit lies: the command says which run failed, that the
    limit is missing, and exits 1."""
    from validation.cli import main
    monkeypatch.setattr(stability, "GRID", (1e-3,))
    monkeypatch.setattr(stability, "BISECTIONS", 0)
    monkeypatch.setattr(stability, "DURATION", 0.2)
    cfg = tmp_path / "health.toml"
    cfg.write_text("[plant]\nkind = \"exudyn\"\nnewton_tolerance = 1e-16\n")
    status = main(["stability", str(cfg), "--plant", "exudyn", "--arm", "default",
                   "--out", str(tmp_path / "out"), "--workers", "1", "--no-progress"])
    assert status == 1
    out = capsys.readouterr().out
    assert "1 limit(s) missing: a run failed where the limit is" in out and "at 1 ms" in out
    text = (tmp_path / "out" / "stability.md").read_text()
    assert "FAILED at 1 ms" in text


def test_a_limit_that_moves_under_refinement_is_mapped_again_finer(tmp_path, monkeypatch):
    """The PBC fed the true state on the default arm's truth plant, started on a mesh too
    coarse for it (ANCF 1 el/link: the FE prediction is 3.04 ms, against 2.725 at ANCF 2
    and 2.738 at ANCF 4 and 8).  Known bad: on ANCF 1 its bracket is [2.82, 3.16] ms, and
    2.82 ms diverges on the refined sequence: not converged.  One level finer (ANCF 2, half
    the step) 2.82 ms is still stable (marginal there: growth −0.06 1/s) and diverges on
    ANCF 4 with a quarter of the step: not converged either.  Two levels finer (ANCF 4, a
    quarter of the step) the bracket [2.51, 2.82] ms keeps its outcomes on ANCF 8 and 16
    (half and a quarter of that step) and on GE 32, and contains the converged FE
    prediction, 2.738 ms (exact ZOH eigenvalues of the FE linearisation)."""
    monkeypatch.setattr(stability, "GRID", (2e-3, 5e-3))
    base = scenario_from_mapping({"observer": {"kind": "none"},
                                  "plant": {"kind": "exudyn",
                                            "mesh": {"elements_per_link": [1, 1]}}})
    cases = stability.cases_from_scenarios([base], plants=["exudyn"], arms=["default"])
    results, summary = stability.stability_map(cases, tmp_path, progress=False)
    assert summary.failed == 0
    (pbc,) = results
    assert pbc.case.level == 2 and pbc.mesh_converged is True, pbc.mesh
    assert pbc.discretisation.startswith("ANCF 4 el/link")
    low, high = pbc.divergence.largest, pbc.divergence.first_bad
    assert low < 2.738e-3 < high and high / low < 1.15, (low, high)
    assert low < pbc.predicted < high  # the prediction on ANCF 4: 2.738 ms
    level0 = stability.load_stability(tmp_path, cases=cases)
    assert level0[0].mesh_converged is False and level0[0].divergence.largest > 2.8e-3


def test_a_growing_run_is_diverging_before_it_leaves_the_bounds():
    """Known bad: the default arm's PBC at 2.76 ms on the truth plant (limit 2.738 ms)
    grows at +4 1/s and is still inside the divergence bounds after 1 s; known good: at
    2.6 ms its fastest motion decays."""
    from validation.run.loop import run_scenario
    outcomes = {}
    for Ts in (2.6e-3, 2.76e-3):
        result = run_scenario(scenario_from_mapping({
            "plant": {"kind": "exudyn", "step": Ts / 6}, "Ts": Ts, "duration": 1.0,
            "transient": 0.5, "initial_state": "reference", "observer": {"kind": "none"}}))
        assert result.status == "ok"
        outcomes[Ts] = stability.outcome(_row("ok", metrics=all_metrics(result)))
    assert outcomes[2.6e-3][0] == "stable", outcomes
    assert outcomes[2.76e-3][0] == "diverged" and "growing" in outcomes[2.76e-3][1], outcomes
