"""The sampled-data stability map explains why the paper's own arm diverges at 1 ms, and
states its limits at the resolution they claim (bisected to a tolerance, judged on the
refined sequence)."""
import math
from pathlib import Path
from types import SimpleNamespace

import pytest

from validation.report.verdict_tables import stability_rows
from validation.run.metrics import all_metrics
from validation.verdicts import stability
from validation.verdicts.bisection import GOOD, Lattice, limit_of, next_points
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping

#: A tolerance wider than every step of a grid: the grid alone, no bisection.
GRID_ONLY = 10.0


def test_a_small_map_finds_the_table1_limit(tmp_path, monkeypatch):
    # Three control periods and no bisection keep this short (1 s runs).
    monkeypatch.setattr(stability, "GRID", (2e-4, 1e-3, 5e-3))
    monkeypatch.setattr(stability, "DURATION", 1.0)
    scenarios = [scenario_from_mapping({})]
    cases = stability.cases_from_scenarios(scenarios, plants=["reduced"],
                                           arms=["default", "table1"])
    results, summary = stability.stability_map(cases, tmp_path, progress=False,
                                               tolerance=GRID_ONLY)
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
    r = stability._result(case, [tested])
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
    r = stability._result(case, [tested])
    # Nothing is known at 2 ms: both limits stop below it, and it is not a divergence.
    assert r.divergence.largest == 1e-3 and r.divergence.outcome == "failed"
    assert r.failed == [2e-3]
    assert "FAILED at 2 ms" in stability_rows([r])[0]["notes"]
    # A failure is not bisected towards: it says nothing about where a limit lies.
    assert next_points(tested, Lattice(stability.GRID, 0.01), ()) == set()


def test_a_stability_campaign_with_a_solver_failure_exits_1(tmp_path, monkeypatch, capsys):
    """A Newton tolerance below ANCF's round-off makes Exudyn give up (as in the
    reliability suite) where the limit lies: the command says which run failed, that the
    limit is missing, and exits 1."""
    from validation.cli import main
    monkeypatch.setattr(stability, "GRID", (1e-3,))
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


# --- limits to a stated tolerance, judged on the refined sequence -------------------------------
def _reduced_pbc(out, tolerance):
    """The stability map of the PBC fed the true state on the default arm's reduced plant
    (14 runs of 2 s, about a second)."""
    s = scenario_from_mapping({"observer": {"kind": "none"}})
    cases = stability.cases_from_scenarios([s], plants=["reduced"], arms=["default"])
    (result,), summary = stability.stability_map(cases, out, progress=False,
                                                 tolerance=tolerance)
    assert summary.failed == 0
    return result


def _smo_map(out, tolerance):
    """The map of the PBC with the paper's SMO on the default arm's reduced plant (an
    observer: its search starts from the 7 grid periods); (result, summary)."""
    s = scenario_from_mapping({"observer": {"kind": "smo-paper"}})
    cases = stability.cases_from_scenarios([s], plants=["reduced"], arms=["default"])
    (result,), summary = stability.stability_map(cases, out, progress=False,
                                                 tolerance=tolerance)
    return result, summary


def test_a_finer_tolerance_refines_the_map_stored_in_the_folder(tmp_path):
    """Known good: a 1 % map, then 0.5 % into the same folder: the second runs only the
    periods inside the 1 % brackets (the lattices nest: every 1 % period is a 0.5 % one),
    and its brackets are the fresh 0.5 % map's.  Known bad: the 0.5 % map made afresh
    runs the grid and every bisection again."""
    coarse, first = _smo_map(tmp_path / "map", 0.01)
    fine, refine = _smo_map(tmp_path / "map", 0.005)
    fresh, afresh = _smo_map(tmp_path / "fresh", 0.005)
    assert set(coarse.tested) <= set(fine.tested) and refine.skipped == 0
    assert fine.divergence.width <= 0.005
    for name in ("divergence", "tracking"):
        a, b = getattr(fine, name), getattr(fresh, name)
        assert (a.largest, a.first_bad) == (b.largest, b.first_bad), name
    # each limit's 1 % bracket holds one 0.5 % point: at most one run a limit
    assert refine.planned <= 2 < afresh.planned, (first.planned, refine.planned,
                                                  afresh.planned)


@pytest.mark.parametrize("tolerance", [0.05, 0.01])
def test_the_reduced_pbc_limit_to_a_tolerance_contains_the_zoh_prediction(tmp_path, tolerance):
    """Known good: bisected to 5 % and to 1 %, the bracket is within the tolerance and,
    with the outcome test's band below it (a run growing slower than 1.5 1/s reads
    stable: 0.013 ms at 1 %), contains the exact-ZOH prediction, 3.051 ms."""
    r = _reduced_pbc(tmp_path, tolerance)
    assert r.predicted == pytest.approx(3.051e-3, rel=1e-3)
    assert r.divergence.width <= tolerance
    # The search starts at the prediction's lattice cell: at 5 % that cell, (2.99, 3.07] ms,
    # brackets the limit in its two runs; at 1 % the loop turns unstable 0.3 % above the
    # prediction: one cell up, 3 runs (2 if the prediction, resolved to 0.1 %, lands above
    # the lattice point 3.0511 ms it now lies 0.01 % below).  The grid and a bisection
    # from it took 14 runs.
    assert r.runs <= {0.05: 2, 0.01: 3}[tolerance], r.runs
    low, high = r.resolved["divergence"].interval()
    assert low <= r.predicted < high, (low, high)
    assert r.resolved["divergence"].verdict == ""  # the reduced plant: no refined sequence


def test_half_a_percent_resolves_the_frozen_time_predictions_error(tmp_path):
    """At 0.5 % the bracket (3.062, 3.073] ms and its band (0.007 ms) lie above the
    prediction, by less than 0.5 %: the nonlinear loop moving along the reference turns
    unstable at 3.061 ms (its growth rate crosses zero between 3.056 and 3.062 ms), 0.3 %
    above the worst frozen operating point's linear limit.  The validity check reads
    "no" there, as it should: the tolerance resolves what the prediction leaves out."""
    r = _reduced_pbc(tmp_path, 0.005)
    low, _ = r.resolved["divergence"].interval()
    assert r.divergence.width <= 0.005
    assert r.predicted < low < 1.005 * r.predicted


def test_a_fixed_number_of_bisections_does_not_tighten(tmp_path, monkeypatch):
    """Known bad: the map of before — three geometric bisections after the grid, a ratio
    (5/2)^(1/8) = 1.121 whatever was asked — gives the same 12 % bracket at 5 % and at
    1 %: the width criterion above fails it."""
    monkeypatch.setattr(stability, "Lattice", lambda grid, tolerance: Lattice(grid, 0.13))
    widths = {tol: _reduced_pbc(tmp_path / str(tol), tol).divergence.width
              for tol in (0.05, 0.01)}
    assert widths[0.05] == widths[0.01] == pytest.approx(2.5 ** (1 / 8) - 1)
    assert widths[0.01] > 0.05


def _threshold(limit):
    """A synthetic loop: stable up to ``limit``, diverged above."""
    return lambda Ts: ("stable", "") if Ts <= limit else ("diverged", "grows")


def _search(lattice, loop, hints):
    """Run the bracket search of one level to its end; (tested, rounds)."""
    tested, rounds = {}, 0
    while points := next_points(tested, lattice, hints):
        tested |= {Ts: loop(Ts) for Ts in points}
        rounds += 1
    return tested, rounds


@pytest.mark.parametrize("tolerance", [0.1, 0.01, 0.005, 0.001])
def test_a_bracket_is_bisected_to_the_tolerance_on_one_lattice(tolerance):
    """Known good: every limit in the grid's range ends in a bracket within the tolerance,
    and the finer level starting from it finds a limit that did not move in two runs, one
    that moved by 0.7 % in a few more; a coarser tolerance's points are points of every
    finer lattice, bit for bit (its runs are reused)."""
    grid = stability.GRID
    lattice = Lattice(grid, tolerance)
    assert set(Lattice(grid, 0.1).points) <= set(lattice.points)
    for limit in (1.234e-4, 7.77e-4, 2.77e-3, 9.1e-3):
        tested, rounds = _search(lattice, _threshold(limit), grid)
        found = limit_of(tested, GOOD["divergence"])
        assert found.largest <= limit < found.first_bad and found.width <= tolerance
        assert len(tested) <= len(grid) + lattice.depth  # one run per bisection
        hints = {found.largest, found.first_bad}
        again, _ = _search(lattice, _threshold(limit), hints)
        assert len(again) == 2
        moved, _ = _search(lattice, _threshold(0.993 * limit), hints)
        lower = limit_of(moved, GOOD["divergence"])
        assert lower.largest <= 0.993 * limit < lower.first_bad and lower.width <= tolerance


def test_a_search_starts_at_the_cell_of_the_predicted_limit():
    """Known good: a prediction in the limit's cell brackets it in its two runs; one 10 %
    off (either way) still ends in the same cell, stepping outwards.  Known bad for a
    start: a prediction beyond the lattice starts at its end point; none (NaN) or an
    unbounded one (inf: the LQR's) starts from the whole grid."""
    lattice = Lattice(stability.GRID, 0.01)
    limit = 2.77e-3
    exact, _ = _search(lattice, _threshold(limit), lattice.cell(limit))
    assert len(exact) == 2
    for predicted in (0.9 * limit, 1.1 * limit):
        tested, _ = _search(lattice, _threshold(limit), lattice.cell(predicted))
        found = limit_of(tested, GOOD["divergence"])
        assert found.largest <= limit < found.first_bad and found.width <= 0.01
        assert len(tested) < len(stability.GRID) + lattice.depth
    assert lattice.cell(2.5e-6) == {1e-4} and lattice.cell(0.5) == {1e-2}
    assert lattice.cell(math.nan) == lattice.cell(math.inf) == set(stability.GRID)


def test_a_case_with_an_observer_starts_from_the_grid(tmp_path, monkeypatch):
    """Known bad for a start at the prediction: the PBC with the position-only sign SMO
    (the prediction is the PBC's fed the true state, 3.05 ms) diverges 18 % below it on
    the default arm's reduced plant, and is stable again at 3.05 ms — a search started
    there brackets (3.05, 3.07] ms and misses it.  From the grid the map finds it."""
    from validation.batch.campaign import expand, load_campaign
    from validation.cli.campaigns import campaigns_dir
    runs = expand(load_campaign(campaigns_dir() / "paper.toml"))
    s = next(r.scenario for r in runs if r.scenario.observer.kind == "smo-pos")
    (case,) = stability.cases_from_scenarios([s], plants=["reduced"], arms=["default"])
    assert stability._start(case, Lattice(stability.GRID, 0.01), None) == set(stability.GRID)
    (r,), _ = stability.stability_map([case], tmp_path, progress=False)
    assert r.divergence.first_bad < 0.9 * r.predicted, (r.divergence, r.predicted)
    # Started at the prediction's cell, the same map misses it.
    monkeypatch.setattr(stability, "_start",
                        lambda case, lattice, prediction: lattice.cell(r.predicted))
    (seeded,), _ = stability.stability_map([case], tmp_path / "seeded", progress=False)
    # It claims no divergence 20 % above the divergence the grid found (3.05 against
    # 2.51 ms): far from any round-off of the prediction (0.1 %) or the lattice (1 %).
    assert seeded.divergence.largest > 1.1 * r.divergence.first_bad


def test_a_limit_beyond_the_grid_is_not_bisected():
    lattice = Lattice(stability.GRID, 0.01)
    for limit in (5e-5, 0.02):
        tested, rounds = _search(lattice, _threshold(limit), stability.GRID)
        assert rounds == 1 and len(tested) == len(stability.GRID)


def _refined_search(thresholds):
    """Run a truth-plant case's search on synthetic loops, one threshold per level
    (`_threshold`), from the grid, to its end; (search, runs)."""
    case = stability.StabilityCase("pbc", "exudyn", "table1", scenario_to_mapping(
        scenario_from_mapping({"plant": {"kind": "exudyn"}})))
    assert case.truth
    lattice, search, runs = Lattice(stability.GRID, 0.01), stability._Search(
        case, set(stability.GRID)), 0
    while points := search.next_points(lattice, True):
        search.levels[search.at.level] |= {Ts: _threshold(thresholds[search.at.level])(Ts)
                                           for Ts in points}
        runs += len(points)
    return search, runs


#: A limit moving as Table 1's with a sign SMO on the truth plant (ANCF 4, 8, 16): from
#: 0.293 to 0.1286 ms, then below the grid's 0.1 ms.
RUNS_OFF = (0.2933e-3, 0.1286e-3, 0.05e-3)


def test_a_limit_running_off_the_grid_is_not_bisected_on_the_way(monkeypatch):
    """Known good: a limit that moved from 0.293 to below 0.134 ms (by 2.2×, more than
    its bracket's 34 % width) and would move past 0.1 ms by as much again is left as
    (0.1, 0.134] ms on level 1; level 2 finds no bracket (below the grid) and the verdict
    is "not converged" either way, in fewer runs.  Known bad (the rule off: every level
    bisected to 1 %): the same verdict, level 1 at 1 %, more runs."""
    search, runs = _refined_search(RUNS_OFF)
    (_, low1, high1), (_, low2, high2) = [
        (level, lim.largest, lim.first_bad) for level, lim in enumerate(
            stability._limits(search.levels)["divergence"][1:], 1)]
    assert low1 == 1e-4 and high1 / low1 - 1 > 0.3 and math.isnan(low2) and high2 == 1e-4
    monkeypatch.setattr(Lattice, "runs_off", lambda self, limit, before: False)
    bisected, all_runs = _refined_search(RUNS_OFF)
    level1 = limit_of(bisected.levels[1], GOOD["divergence"])
    assert level1.width <= 0.01 and level1.largest <= RUNS_OFF[1] < level1.first_bad
    # Level 1: 10 runs instead of 16 (its bisection); level 2 from (0.1, 0.134]: 2 runs
    # instead of 8 stepping down from 0.129 ms.  The real map took 38 per such case.
    assert (runs, all_runs) == (26, 38)
    for s in (search, bisected):
        (lims,) = [v for k, v in stability._limits(s.levels).items() if k == "divergence"]
        assert stability._resolve(s.case, lims, final=True).verdict == "not converged"


def test_a_level_left_unbisected_is_bisected_when_the_finer_one_brackets_the_limit():
    """Known good for the rule above: when level 2 brackets the limit after all (0.105
    ms, inside the grid), level 1 is bisected then — every level ends within 1 %, with
    the brackets of a search that bisected every level as it went, and a judged
    verdict; the rule of `Lattice.runs_off` said no verdict reads an unbisected one."""
    thresholds = RUNS_OFF[:2] + (0.105e-3,)
    search, _ = _refined_search(thresholds)
    # 38 runs; bisecting level 1 as it went took 42 (14, 16, 12: level 2 stepped down
    # from 0.129 ms instead of bisecting (0.1, 0.134]).
    assert [len(t) for t in search.levels] == [14, 16, 8]
    for level, tested in enumerate(search.levels):
        limit = limit_of(tested, GOOD["divergence"])
        assert limit.width <= 0.01 and limit.largest <= thresholds[level] < limit.first_bad


def test_a_limit_beyond_the_grid_on_every_level_says_so():
    """Known good: a truth-plant limit above 10 ms (20 ms: the synthetic loop of
    `_threshold`) is mapped one level finer all the same — a finer mesh may bring it
    inside the grid — in one run at 10 ms, stays above it, and reads "beyond the grid"
    naming both levels, in the verdict, the stability table and stability.csv (before:
    "unresolved … on every level" after level 0 alone).  Below 0.1 ms on every level,
    "below the grid"."""
    search, runs = _refined_search((0.02, 0.02, 0.02))
    assert runs == len(stability.GRID) + 1 and len(search.levels) == 2
    assert search.levels[1] == {1e-2: ("stable", "")}
    result = stability._result(search.case, search.levels, predicted=math.nan)
    for name in ("divergence", "tracking"):
        resolved = result.resolved[name]
        assert resolved.verdict == "beyond the grid", resolved.text()
        assert resolved.text().startswith("beyond the grid: above 10 ms, the largest period "
                                          "tested, on every level (ANCF 4 el/link")
        assert "ANCF 8 el/link" in resolved.text() and "not converged" not in resolved.text()
        assert resolved.interval() == (1e-2, math.inf)  # no band: nothing diverged
    row = stability_rows([result])[0]
    assert row["divergence_convergence"] == row["tracking_convergence"] == "beyond the grid"
    assert "divergence: beyond the grid" in row["mesh"]
    below, _ = _refined_search((5e-5, 5e-5, 5e-5))
    (lims,) = [stability._limits(below.levels)["divergence"]]
    assert stability._resolve(below.case, lims, final=True).verdict == "below the grid"


@pytest.mark.parametrize("thresholds", [
    (0.02, 0.005, 0.02),  # above the grid, inside it one level finer, above again
    (0.005, 0.02, 0.02),  # inside the grid, then above it
])
def test_a_limit_the_levels_disagree_about_is_not_converged(thresholds):
    """Known bad for the rule above: a limit above the grid on some levels and bracketed
    on another is mapped to the finest level and reads "not converged", the levels'
    brackets side by side — never "beyond the grid"."""
    search, _ = _refined_search(thresholds)
    assert len(search.levels) == stability.MAX_LEVEL + 1
    lims = stability._limits(search.levels)["divergence"]
    resolved = stability._resolve(search.case, lims, final=True)
    assert resolved.verdict == "not converged" and "beyond the grid" not in resolved.text()
    assert "(10, —]" in resolved.text() and "(5, 5.027]" in resolved.text()


def test_table1_on_one_element_per_link_is_not_converged(tmp_path, monkeypatch):
    """Known bad mesh: Table 1's arm (no stator inertia: the joint-2 mobility grows as
    elements³) on ANCF 1 el/link, the PBC fed the true state.  Bisected to 1 % its limit
    is (0.181, 0.182] ms; on ANCF 2 and 4 (half and a quarter of the step) it diverges at
    the smallest period tested: not converged, the levels side by side."""
    monkeypatch.setattr(stability, "GRID", (1e-4, 2e-4, 5e-4))  # the limit is below 0.5 ms
    s = scenario_from_mapping({"observer": {"kind": "none"},
                               "plant": {"kind": "exudyn", "mesh": {"elements_per_link": [1, 1]}}})
    cases = stability.cases_from_scenarios([s], plants=["exudyn"], arms=["table1"])
    (r,), summary = stability.stability_map(cases, tmp_path, progress=False, tolerance=0.01)
    assert summary.failed == 0
    resolved = r.resolved["divergence"]
    assert resolved.verdict == "not converged" and r.case.level == stability.MAX_LEVEL
    (_, low0, high0), *finer = resolved.levels
    assert 1.8e-4 < low0 < high0 < 1.01 * low0 + 1e-12
    assert all(math.isnan(low) and high == 1e-4 for _, low, high in finer)
    row = stability_rows([r])[0]
    assert row["divergence_convergence"] == "not converged" and "ANCF 2 el/link" in row["mesh"]


def test_a_limit_still_moving_at_the_finest_level_is_extrapolated(tmp_path):
    """The PBC fed the true state on the default arm, started on a mesh too coarse for it
    (ANCF 1 el/link).  Bisected to 1 %: (3.051, 3.073] ms on ANCF 1, (2.820, 2.840] on
    ANCF 2, (2.740, 2.760] on ANCF 4 — moving by more than the width at every level, by
    less each time: the Richardson estimate of the converged limit (order 1.5), 2.71 ±
    0.06 ms, contains the converged FE prediction 2.738 ms (exact ZOH eigenvalues of the
    FE linearisation); the ANCF 1 bracket alone (known bad) does not."""
    base = scenario_from_mapping({"observer": {"kind": "none"},
                                  "plant": {"kind": "exudyn",
                                            "mesh": {"elements_per_link": [1, 1]}}})
    cases = stability.cases_from_scenarios([base], plants=["exudyn"], arms=["default"])
    (pbc,), summary = stability.stability_map(cases, tmp_path, progress=False,
                                              tolerance=0.01)
    assert summary.failed == 0 and pbc.case.level == 2
    assert pbc.discretisation.startswith("ANCF 4 el/link")
    resolved = pbc.resolved["divergence"]
    assert resolved.verdict == "extrapolated", resolved.text()
    low, high = resolved.interval()
    assert low < 2.738e-3 < high and resolved.error < 0.1 * resolved.estimate
    (_, low0, high0), *_ = resolved.levels
    assert not low0 < 2.738e-3 < high0


@pytest.mark.slow  # 19 truth-plant runs, three meshes, the FE prediction: 1-6 min
def test_the_default_arms_pbc_limit_is_converged_at_one_percent(tmp_path):
    """What is checked from outside: ``flexarm stability`` of the PBC fed the true state
    on the default arm's truth plant gives a bracket ≤ 1 % wide, converged, containing
    2.738 ms (the exact-ZOH prediction on the converged FE model) within its stated
    error.  Measured: ANCF 4 (2.760, 2.780] ms, ANCF 8 (2.740, 2.760], ANCF 16 (2.740,
    2.760]: converged at ANCF 16, error ≤ 0.02 ms (the span of the last two brackets)."""
    import csv

    from validation.cli import main
    (tmp_path / "pbc.toml").write_text('[controller]\nkind = "pbc"\n')
    assert main(["stability", str(tmp_path / "pbc.toml"), "--plant", "exudyn", "--arm",
                 "default", "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    with (tmp_path / "out" / "stability.csv").open() as fh:
        (row,) = [r for r in csv.DictReader(fh) if r["case"] == "pbc"]
    low, high = float(row["no_divergence_s"]), float(row["first_divergence_s"])
    error = float(row["divergence_error_s"])
    assert high / low - 1 <= 0.01 and row["divergence_convergence"] == "converged"
    assert low - error <= 2.738e-3 < high + error


def test_the_refined_sequence_rule():
    """`resolve_limit` on brackets (ms): overlapping → converged, the error the span of
    the two; moving and shrinking by a constant ratio → extrapolated (Richardson, order 2
    here); moving towards zero (a limit that is a property of the mesh) → not converged."""
    from validation.verdicts.resolution import resolve_limit
    ms = lambda *pairs: [(f"level {k}", 1e-3 * a, 1e-3 * b) for k, (a, b) in enumerate(pairs)]  # noqa: E731
    converged = resolve_limit(ms((2.76, 2.78), (2.74, 2.76), (2.74, 2.76)), final=True)
    assert converged.verdict == "converged"
    assert converged.error == pytest.approx(0.02e-3) and "error" in converged.text()
    first = resolve_limit(ms((2.76, 2.78), (2.74, 2.76)), final=False)
    assert first.verdict == "not converged"  # touching is not overlapping: mapped finer
    shrinking = resolve_limit(ms((2.90, 2.91), (2.80, 2.81), (2.775, 2.785)), final=True)
    assert shrinking.verdict == "extrapolated"
    assert shrinking.order == pytest.approx(2.0, abs=0.01)
    assert shrinking.estimate == pytest.approx(2.7717e-3, rel=1e-3)
    assert shrinking.interval()[0] < shrinking.estimate < shrinking.interval()[1]
    to_zero = resolve_limit(ms((1.6, 1.61), (0.2, 0.201), (0.025, 0.0252)), final=True)
    assert to_zero.verdict == "not converged" and "level 2" in to_zero.text()
    # outside the grid: on one level, not checked (the reduced plant: no verdict); on
    # every level, beyond (or below) it; on one side and then the other, not converged
    nan = math.nan
    assert resolve_limit(ms((10, nan)), final=False).verdict == "not checked"
    assert resolve_limit(ms((10, nan)), final=True, refined=False).verdict == ""
    assert resolve_limit(ms((10, nan), (10, nan)), final=False).verdict == "beyond the grid"
    assert resolve_limit(ms((nan, 0.1), (nan, 0.1)), final=False).verdict == "below the grid"
    assert resolve_limit(ms((10, nan), (nan, 0.1)), final=True).verdict == "not converged"


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


@pytest.mark.parametrize("text, flag, where", [
    ("", ["--tolerance", "0"], "--tolerance"),
    ("[stability]\ntolerance = 0.9\n", [], "stability.tolerance"),
    ('[stability]\ntolerance = "1 %"\n', [], "stability.tolerance"),
    ("[stability]\ntol = 0.01\n", [], "stability.tol: unknown key"),
    # the file's value is checked when the flag wins too (issue 59: it was ignored, exit 0)
    ("[stability]\ntolerance = 7\n", ["--tolerance", "0.05"], "stability.tolerance"),
    ("[stability]\ntolerance = 0.05\n", ["--tolerance", "7"], "--tolerance"),
])
def test_a_bad_tolerance_is_refused_in_one_line_writing_nothing(tmp_path, capsys, text,
                                                                 flag, where):
    from validation.cli import main
    cfg = tmp_path / "s.toml"
    cfg.write_text('[controller]\nkind = "pd"\n' + text)
    status = main(["stability", str(cfg), "--plant", "reduced", "--arm", "default",
                   "--out", str(tmp_path / "out"), "--no-progress", *flag])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and where in err, err
    assert not (tmp_path / "out").exists()


def test_a_report_reads_the_maps_predictions_made_by_this_code(tmp_path, monkeypatch):
    """The map keeps its predictions beside its runs (predictions.json): rebuilt from the
    folder (as a report does) the map reads them, no case linearised again.  Known bad:
    predictions made by other code are not read, the case is linearised again."""
    from validation.verdicts import predictions, sampled
    made = _reduced_pbc(tmp_path, 0.05)
    monkeypatch.setattr(sampled, "predicted_period", lambda config: 42.0)  # if asked: 42 s
    (again,) = stability.load_stability(tmp_path)
    assert again.predicted == made.predicted == pytest.approx(3.051e-3, rel=1e-3)
    monkeypatch.setattr(predictions, "_made_by", lambda: "other code")
    (stale,) = stability.load_stability(tmp_path)
    assert stale.predicted == 42.0


def test_stored_predictions_outlive_an_edit_of_a_report_not_of_their_code():
    """Known-good: the report's modules are not code a prediction depends on (editing
    one keeps the stored predictions); known-bad: the linearisation's module, the laws
    and the reduced model are (editing one drops them)."""
    import validation
    from validation.batch.fingerprint import module_sources
    from validation.verdicts.predictions import MADE_BY
    root = Path(validation.__file__).resolve().parents[1]
    files = {p.relative_to(root).as_posix() for p in module_sources(MADE_BY)}
    assert not any(f.startswith(("validation/report/", "validation/cli/")) for f in files)
    assert {"validation/verdicts/sampled.py", "validation/verdicts/linear.py",
            "validation/run/laws.py", "reduced_model/model.py"} <= files


def test_maps_into_one_folder_keep_each_others_predictions(tmp_path, monkeypatch):
    """A second map into the same folder adds its predictions to the first's (inf kept as
    inf: the LQR's); predictions made by other code are dropped, not merged."""
    from validation.verdicts import predictions
    predictions.write_predictions(tmp_path, {"first": 3.051e-3})
    predictions.write_predictions(tmp_path, {"second": math.inf})
    assert predictions.read_predictions(tmp_path) == {"first": 3.051e-3,
                                                      "second": math.inf}
    monkeypatch.setattr(predictions, "_made_by", lambda: "other code")
    assert predictions.read_predictions(tmp_path) == {}
    predictions.write_predictions(tmp_path, {"third": 1e-3})
    assert predictions.read_predictions(tmp_path) == {"third": 1e-3}


# --- the three-link arm -------------------------------------------------------------------------
#: Computed torque fed the true state on the three-link arm, on a reference 100× slower
#: than the paper's (θ_i ≤ 0.04 rad over the 2 s runs): the arm stays at the stretched-out
#: pose that limits the loop (3.42 ms there, ~5 ms at the paper reference's later
#: poses, where a frozen-time prediction of a moving loop is only a lower bound: the
#: paper's reference gives a reduced-plant bracket (5.250, 5.278] ms), so the frozen-time
#: prediction is the loop's own.  Its limit lies inside the grid; the PBC's (12.4 ms
#: predicted) does not.
THREE_LINK_CT = ('arm = "three-link"\n[controller]\nkind = "ct"\n[observer]\nkind = "none"\n'
                 '[reference]\nomega = [0.00314, 0.00628, 0.00942]\n')


def _three_link_ct(plants):
    import tomllib
    scenario = scenario_from_mapping(tomllib.loads(THREE_LINK_CT))
    return stability.cases_from_scenarios([scenario], plants=plants)


def test_the_three_link_arms_reduced_limit_contains_its_zoh_prediction(tmp_path):
    """Known good: bisected to 1 %, the reduced plant's bracket with its outcome band
    contains the exact-ZOH prediction of the N-link loop, 3.424 ms (measured: (3.421,
    3.446] ms, 2 runs)."""
    (r,), summary = stability.stability_map(_three_link_ct(["reduced"]), tmp_path,
                                            progress=False, tolerance=0.01)
    assert summary.failed == 0 and r.case.arm == "three-link"
    assert r.predicted == pytest.approx(3.424e-3, rel=2e-3)
    assert r.divergence.width <= 0.01
    low, high = r.resolved["divergence"].interval()
    assert low <= r.predicted < high, (low, high)


def test_the_three_link_arms_truth_limit_is_converged_on_its_fe_prediction(tmp_path):
    """What is checked from outside: ``flexarm stability`` on the three-link arm's truth
    plant bisects to 1 %, converged under refinement, and the bracket contains the exact-ZOH
    prediction on the FE arm's linearisation, 3.009 ms.  Measured: ANCF 4 (3.051, 3.073]
    ms (the step of 0.75 ms damps the Nyquist mode), ANCF 16 with a quarter of the step
    (3.008, 3.029] ms, converged."""
    import csv

    from validation.cli import main
    (tmp_path / "ct.toml").write_text(THREE_LINK_CT)
    assert main(["stability", str(tmp_path / "ct.toml"), "--plant", "exudyn", "--arm",
                 "three-link", "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    with (tmp_path / "out" / "stability.csv").open() as fh:
        (row,) = list(csv.DictReader(fh))
    low, high = float(row["no_divergence_s"]), float(row["first_divergence_s"])
    error = float(row["divergence_error_s"])
    assert high / low - 1 <= 0.01 and row["divergence_convergence"] == "converged"
    assert low - error <= 3.009e-3 < high + error


def test_every_joints_tracking_is_judged():
    """Known bad: a three-link run that tracks on joints 1 and 2 and not on joint 3 has
    lost tracking (reading joints 1 and 2 alone would call it stable)."""
    row = SimpleNamespace(status="ok", message="", metrics={
        "track_max_1": 0.01, "track_max_2": 0.01, "track_max_3": 0.2})
    assert stability.outcome(row)[0] == "lost tracking"
    assert stability.outcome(_row("ok", 0.01))[0] == "stable"
