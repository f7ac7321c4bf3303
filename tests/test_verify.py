"""Verdicts over uncertainty: the statistics cover what they claim, the optimiser finds a
planted minimum, the uncertainty set draws what a random sweep draws, a counterexample
replays to its robustness, and an interrupted search resumes to the same answer."""
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.stats import binom

from validation.batch.campaign import campaign_from_mapping, expand
from validation.batch.worker import execute_run
from validation.run.arms import parameter_value
from validation.run.config import ConfigError
from validation.run.tomlfiles import load_toml
from validation.verdicts.search import minimise
from validation.verdicts.statistics import SequentialTest, clopper_pearson, sprt
from validation.verdicts.uncertainty import load_systems

from campaign_testing import stored_count
from cli_testing import flexarm


# --- statistics -------------------------------------------------------------------------------
def _wald(successes: int, n: int) -> tuple[float, float]:
    """The textbook normal-approximation interval: a known-bad case for the coverage test."""
    p = successes / n
    half = 1.959964 * math.sqrt(p * (1 - p) / n)
    return p - half, p + half


@pytest.mark.parametrize("p", [0.9, 0.95, 0.99])
def test_the_intervals_cover_the_true_p_in_95_percent_of_experiments(p):
    n, level, experiments = 59, 0.95, 1000
    k = np.random.default_rng(20).binomial(n, p, experiments)
    interval = {s: clopper_pearson(s, n, level) for s in range(n + 1)}
    covered = np.mean([interval[s][0] <= p <= interval[s][1] for s in k])
    assert covered >= level
    # Exactly (the binomial distribution of the successes), not only in 1000 experiments:
    exact = sum(binom.pmf(s, n, p) for s in range(n + 1) if interval[s][0] <= p <= interval[s][1])
    assert exact >= level
    # The normal approximation does not: at p = 0.99, 59 successes out of 59 (probability
    # 0.55) give the interval [1, 1].
    if p == 0.99:
        wald = np.mean([_wald(s, n)[0] <= p <= _wald(s, n)[1] for s in k])
        assert wald < 0.5


def test_no_failure_in_59_draws_certifies_095_one_sided():
    # two-sided at 0.90 = one-sided at 0.95: 0.05^(1/59) = 0.9505
    assert clopper_pearson(59, 59, 0.90)[0] == pytest.approx(0.05 ** (1 / 59), rel=1e-9)
    assert clopper_pearson(59, 59, 0.95)[0] == pytest.approx(0.025 ** (1 / 59), rel=1e-9)


def test_the_sequential_test_decides_within_its_error_probabilities():
    test = SequentialTest(p0=0.95, indifference=0.025, alpha=0.05, beta=0.05)
    rng = np.random.default_rng(5)
    decisions = {p: [sprt(rng.random(2000) < p, test)[0] for _ in range(200)]
                 for p in (0.99, 0.975, 0.925, 0.8)}
    # At the edges of the indifference region the wrong answer has probability <= alpha,
    # beta (Wald's bounds, nearly exact here); well outside it, almost never.
    assert decisions[0.975].count("fails") / 200 <= 0.05 + 0.03  # 200 runs: ±0.03 (2 sd)
    assert decisions[0.925].count("holds") / 200 <= 0.05 + 0.03
    assert decisions[0.99].count("holds") == 200
    assert decisions[0.8].count("fails") == 200
    # Three early failures decide "fails" at once; 56 successes are needed for "holds".
    assert sprt([False, False, False], test) == ("fails", 3)
    assert sprt([True] * 100, test) == ("holds", 56)
    assert sprt([True] * 10, test) == ("inconclusive", 10)


# --- the optimiser ------------------------------------------------------------------------------
PLANTED = np.array([0.9, 0.15, 0.8, 0.3])


def rippled_well(X: np.ndarray) -> np.ndarray:
    """Negative only within 0.045 of PLANTED (2e-5 of the cube's volume), with a ripple of
    local minima around it (one per 0.25 along each axis)."""
    d = X - PLANTED
    return (np.sum(d ** 2, axis=1) - 0.002
            + 0.02 * np.sum(1 - np.cos(8 * np.pi * d), axis=1) / X.shape[1])


@pytest.mark.parametrize("seed", range(5))
def test_the_optimiser_finds_a_planted_minimum(seed):
    x, value, used = minimise(rippled_well, 4, seed=seed, budget=2000, target=0.0)
    assert value < 0 and np.linalg.norm(x - PLANTED) < 0.045
    # Uniform random search with the same budget: 2e-5 of the volume, 4 % chance in 2000.
    U = np.random.default_rng(seed).random((2000, 4))
    assert rippled_well(U).min() > 0


# --- uncertainty sets -----------------------------------------------------------------------
SYSTEM = """\
duration = 1.0
transient = 0.5
initial_state = "reference"
disturbances = [{ kind = "pulse", target = "tau1", amplitude = 1.0, start = 0.6, duration = 0.2 }]
[[requirement]]
name = "track"
claim = "tracking"
[uncertainty]
"true_params.Mp" = { uniform = [0.0, 1.0] }
"disturbances[0].amplitude" = { uniform = [0.0, 4.0] }
"true_params.EI1" = { scale = { uniform = [0.7, 1.3] }, also = ["true_params.EI2"] }
"""


def test_an_uncertainty_set_draws_what_a_random_sweep_draws(tmp_path):
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM)
    (system,) = load_systems(path)
    points, noise = system.uncertainty.draws(6, seed=4)
    data = load_toml(path)
    random = {"samples": 6, "seed": 4, **data.pop("uncertainty")}
    runs = expand(campaign_from_mapping({"name": "c", "scenario": data,
                                         "sweep": [{"name": "r", "random": random}]}))
    assert [r.axes for r in runs] == points
    assert len(set(noise)) == 6  # every draw its own noise realisation
    # the shared draw and the factor of the nominal value
    EI = parameter_value(system.nominal, "true_params.EI1")
    assert all(p["true_params.EI1"] == p["true_params.EI2"] and
               0.7 * EI <= p["true_params.EI1"] <= 1.3 * EI for p in points)
    # the searches' coordinates map the unit cube's corners onto the set's
    low, high = system.uncertainty.at([0, 0, 0]), system.uncertainty.at([1, 1, 1])
    assert (low["true_params.Mp"], high["true_params.Mp"]) == (0.0, 1.0)
    assert high["disturbances[0].amplitude"] == 4.0
    assert high["true_params.EI1"] == pytest.approx(1.3 * EI, rel=1e-15)


def _bad_system(tmp_path, lines: str):
    head, _, _ = SYSTEM.partition("[uncertainty]")
    path = tmp_path / "bad.toml"
    path.write_text(head + "[uncertainty]\n" + lines + "\n")
    return path


@pytest.mark.parametrize("lines, words", [
    ('"true_params.Mq" = { uniform = [0.0, 1.0] }', "uncertainty: true_params.Mq"),
    ('"true_params.Mp" = { uniform = [1.0, 0.0] }', "uncertainty.true_params.Mp: uniform needs"),
    ('"disturbances[3].amplitude" = { uniform = [0.0, 1.0] }', "disturbances[3].amplitude"),
    ('Ts = { choices = [1e-3, 1.5e-3] }', "at Ts = 0.0015"),
    ('"sensors.encoder_noise" = { scale = { loguniform = [0.0, 10.0] } }',
     "loguniform needs low > 0"),
])
def test_a_bad_uncertainty_set_is_refused_naming_it(tmp_path, lines, words):
    with pytest.raises(ConfigError) as info:
        load_systems(_bad_system(tmp_path, lines))
    assert words in str(info.value)


def test_the_cli_refuses_a_bad_set_in_one_line_writing_nothing(tmp_path):
    path = _bad_system(tmp_path, 'Ts = { choices = [1e-3, 1.5e-3] }')
    out = tmp_path / "out"
    done = flexarm(None, "verify", path, "--mode", "estimate", "--out", out, "--workers", "1")
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "Ts = 0.0015" in done.stderr
    assert not out.exists()


# --- falsification end to end ---------------------------------------------------------------------
def _verify(path, out, *extra):
    return flexarm(None, "verify", path, *extra, "--out", out, "--no-progress")


def test_a_counterexample_replays_to_the_same_robustness(tmp_path):
    """A 1 N m pulse already breaks the 0.02 rad tracking bound with payloads near 1 kg
    and 4 N m; the truth plant confirms; its scenario file replays to ρ within 1e-12."""
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM)
    done = _verify(path, tmp_path / "out", "--mode", "falsify", "--budget", "3",
                   "--workers", "1")
    assert done.returncode == 0, done.stderr
    verdict = json.loads((tmp_path / "out" / "verdict.json").read_text())
    assert verdict["found"] and verdict["rho_truth"] < 0 and verdict["simulations"]["truth"] >= 1
    # The counterexample stays one on the refined sequence (mesh and step together) and
    # on the other element formulation, its Richardson ρ within 10 % of |ρ|.
    convergence = verdict["convergence"]
    assert convergence["verdict"] == "converged", convergence
    assert list(convergence["levels"]) == ["ANCF 4 el/link", "ANCF 8 el/link, step/2",
                                           "ANCF 16 el/link, step/4"]
    assert list(convergence["checks"]) == ["ANCF 8 el/link, step/2", "ANCF 16 el/link, step/4",
                                           "GE 32 el/link, step/2"]
    assert all(c["status"] == "diverged" or c["rho"] < 0
               for c in convergence["checks"].values())
    replay = load_toml(tmp_path / "out" / verdict["counterexample"])
    assert replay["plant"]["kind"] == "exudyn"
    _, metrics = execute_run(replay)
    assert metrics["rho_track"] == pytest.approx(verdict["rho_truth"], abs=1e-12, rel=0)
    # The report's section: the verdict, ρ against simulations, Figs. 3-4 on both plants.
    from validation.report.report import write_report
    _, md = write_report(tmp_path / "out", animate=False, progress=False)
    text = md.read_text()
    assert "## Robust verdicts" in text
    assert "| track | claim tracking | counterexample (converged on the refined sequence) |" \
        in text
    captions = [line for line in text.splitlines() if line.startswith("*")]
    assert any("against the simulations" in c for c in captions)
    assert any("counterexample" in c and "(Fig. 3)" in c for c in captions)
    assert "## Runs" not in text  # the search's evaluations are not listed one by one


@pytest.mark.parametrize("rho, checks, expected", [
    # ρ on ANCF 4, then ANCF 8 step/2, ANCF 16 step/4, GE 32 step/2 [rad]
    (-0.2229, [("ok", -0.247), ("ok", -0.256), ("ok", -0.25)], "converged"),  # the issue's
    (-0.01, [("ok", -0.02), ("diverged", None), ("ok", -0.005)], "not converged"),
    (-0.01, [("ok", -0.02), ("ok", 0.004), ("ok", -0.005)], "undecided at this resolution"),
    (-0.01, [("ok", -0.02), ("ok", -0.03), ("ok", 0.001)], "undecided at this resolution"),
    (-0.004, [("ok", -0.002), ("ok", -0.001), ("ok", -0.0015)],  # |ρ| inside its error
     "undecided at this resolution"),
    (0.03, [("ok", 0.035), ("ok", 0.036), ("ok", 0.036)], "converged"),  # holds everywhere
    (0.03, [("ok", 0.02), ("diverged", None), ("ok", 0.05)], "undecided at this resolution"),
    (-0.01, [("ok", -0.02), ("failed", None), ("ok", -0.005)], "check failed"),
])
def test_a_falsification_answer_on_the_refined_sequence(rho, checks, expected, monkeypatch):
    """The rule of `falsify.refined_rho` on stored check runs: a ρ that changes sign
    under refinement (or in the other formulation), or whose |ρ| is inside its error, is
    undecided — not a counterexample; converged when the Richardson ρ's error is at most
    10 % of |ρ| (the issue's −0.2229 rad, −0.247 and −0.256 on the refined meshes: ρ =
    −0.261 ± 0.005, order 1.4); a diverged level (−∞) keeps the sign, not the value."""
    from types import SimpleNamespace

    from validation.run.requirements import Requirement
    from validation.run.scenario import scenario_from_mapping, scenario_to_mapping
    from validation.verdicts import falsify
    from validation.verdicts.mesh import refinements
    req = Requirement(name="track", claim="tracking")
    config = scenario_to_mapping(scenario_from_mapping({"plant": {"kind": "exudyn"}}))
    labels = [r.label for r in refinements(config)]
    rows = {label: SimpleNamespace(status=status, metrics={req.metric: value}, run_id=label)
            for label, (status, value) in zip(labels, checks)}
    monkeypatch.setattr(falsify, "check_runs", lambda rows: [])
    monkeypatch.setattr(falsify, "checks_of", lambda row, by_id: dict(rows))
    ev = SimpleNamespace(out=None, runner=None, store=SimpleNamespace(rows=lambda: []))
    row = SimpleNamespace(config=config, status="ok")
    step = falsify.refined_rho(ev, row, req, rho)  # a question's step:
    next(step)  # it asks for the check runs
    with pytest.raises(StopIteration) as answered:
        step.send([])
    result = answered.value.value
    assert result["verdict"] == expected, result
    assert list(result["levels"]) == ["ANCF 4 el/link", *labels[:2]]
    assert [c["status"] for c in result["checks"].values()] == [c[0] for c in checks]
    if expected == "converged" and rho < -0.1:
        assert result["rho"] == pytest.approx(-0.2613, abs=1e-3)
        assert result["order"] == pytest.approx(1.42, abs=0.01)
        assert result["error"] < 0.1 * abs(result["rho"])


HOLDS = SYSTEM.replace('{ uniform = [0.0, 4.0] }', '{ uniform = [0.0, 0.2] }').replace(
    '"true_params.Mp" = { uniform = [0.0, 1.0] }', '"true_params.Mp" = { uniform = [0.0, 0.2] }')


# slow (23 s: the interrupted-resume contract of a campaign is kept in make test by
# tests/reliability/test_runs_and_campaigns.py).
@pytest.mark.slow
def test_an_interrupted_search_resumes_to_the_same_answer(tmp_path):
    """SIGTERM during a search that finds nothing (it spends its whole reduced budget, 40
    simulations, and confirms its worst cases on the truth plant): exit 143, the finished runs kept; the same command then
    finishes with the verdict of an uninterrupted search with the same seed."""
    path = tmp_path / "system.toml"
    path.write_text(HOLDS)
    args = ("--mode", "falsify", "--budget", "2", "--seed", "3", "--workers", "1")
    whole = _verify(path, tmp_path / "whole", *args)
    assert whole.returncode == 0, whole.stderr
    out = tmp_path / "resumed"
    proc = subprocess.Popen([sys.executable, "-m", "validation.cli", "verify", str(path), *args,
                             "--out", str(out), "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while stored_count(out) < 12 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the search ended before it could be interrupted"
    os.kill(proc.pid, signal.SIGTERM)
    assert proc.wait(timeout=60) == 143
    assert 12 <= stored_count(out) < 42
    assert not (out / "verdict.json").exists()
    resumed = _verify(path, out, *args)
    assert resumed.returncode == 0, resumed.stderr
    first = json.loads((tmp_path / "whole" / "verdict.json").read_text())
    second = json.loads((out / "verdict.json").read_text())
    assert not first["found"] and first["simulations"]["reduced"] == 40
    assert first["simulations"]["truth"] >= 1 and first["worst_case"] == "worst-case.toml"
    assert second == first


def test_an_estimate_stops_when_the_sequential_test_decides(tmp_path):
    """A requirement that always holds and one that never does: Wald's test (p0 = 0.5 ±
    0.1, α = β = 0.05) decides after 8 draws either way (8 × ln(0.4/0.6) crosses
    ln(0.05/0.95)); the interval and the interface keys are in verdict.json."""
    from validation.batch.executor import SerialRunner
    from validation.verdicts.verify import estimate
    head, _, _ = SYSTEM.partition("[[requirement]]")
    path = tmp_path / "system.toml"
    path.write_text(head + '''
[[requirement]]
name = "loose"
formula = "always(abs(theta1 - theta1_ref) <= 1)"
[[requirement]]
name = "impossible"
formula = "always(abs(theta1 - theta1_ref) <= -1)"
[uncertainty]
"true_params.Mp" = { uniform = [0.0, 1.0] }
[verify]
p0 = 0.5
indifference = 0.1
''')
    (system,) = load_systems(path)
    for name, decision in (("loose", "holds"), ("impossible", "fails")):
        out = tmp_path / name
        verdict = estimate(system, system.requirement(name), out, runner=SerialRunner(),
                           samples=40, seed=1, log=lambda *a: None)
        saved = json.loads((out / "verdict.json").read_text())
        assert saved == verdict
        assert {"requirement", "n", "failures", "p_low", "p_high", "level", "method"} <= set(saved)
        assert saved["sequential"]["decision"] == decision and saved["n"] == 8
        assert saved["failures"] == (0 if decision == "holds" else 8)
        low, high = clopper_pearson(8 - saved["failures"], 8, 0.95)
        assert (saved["p_low"], saved["p_high"]) == (low, high)
        assert len(saved["runs"]) == 8 and len(saved["noise_seeds"]) == 8


def test_every_completed_draw_counts(tmp_path, capsys):
    """Issue 37: 6 draws completed and the sequential test decided after 3 (three failures
    at p0 = 0.95: 3 ln 3 crosses ln 19); the interval must be over the 6 (it was over 3,
    the other three thrown away), and verdict.json says which n each method used.  Two
    systems, judged together on one runner."""
    from validation.cli import main
    head, _, _ = SYSTEM.partition("[[requirement]]")
    path = tmp_path / "systems.toml"
    path.write_text("[scenario]\n" + head.replace("duration = 1.0", "duration = 0.6").replace(
        "start = 0.6", "start = 0.55").replace("transient = 0.5", "transient = 0.3") + '''
[[requirement]]
name = "impossible"
formula = "always(abs(theta1 - theta1_ref) <= -1)"
[uncertainty]
"true_params.Mp" = { uniform = [0.0, 1.0] }
[[sweep]]
zip.name = ["pd", "pbc"]
zip.controller.kind = ["pd", "pbc"]
''')
    out = tmp_path / "out"
    assert main(["verify", str(path), "--mode", "estimate", "--samples", "6", "--workers", "1",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("pd", "pbc"):
        saved = json.loads((out / name / "verdict.json").read_text())
        assert saved["draws"] == 6 and saved["n"] == 6 and saved["failures"] == 6
        assert saved["sequential"]["decision"] == "fails" and saved["sequential"]["draws"] == 3
        assert (saved["p_low"], saved["p_high"]) == clopper_pearson(0, 6, 0.95)
        assert len(saved["runs"]) == 6
        assert f"{name}: 6/6 draws" in printed
    assert printed.count("0/6 hold") == 2 and "after 3 draws" in printed


@pytest.mark.slow  # three searches, a Dask cluster: ~1 min
def test_a_search_gives_the_same_verdict_on_every_runner(tmp_path):
    """Serial, two local workers, a Dask cluster: the same seeded search, the same
    verdict (the values come back from the store, bit-identical on every runner)."""
    from validation.batch.executor import make_runner
    from validation.verdicts.verify import falsify
    path = tmp_path / "system.toml"
    path.write_text(HOLDS)
    (system,) = load_systems(path)
    req = system.requirements[0]
    verdicts = {}
    for name, runner in (("serial", lambda: make_runner("local", 1)),
                         ("pool", lambda: make_runner("local", 2, force=True))):
        with runner() as r:
            verdicts[name] = falsify(system, req, tmp_path / name, runner=r, budget=2, seed=5,
                                     log=lambda *a: None)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", host="127.0.0.1") as cluster:
        with make_runner("dask", scheduler=cluster.scheduler_address) as r:
            verdicts["dask"] = falsify(system, req, tmp_path / "dask", runner=r, budget=2,
                                       seed=5, log=lambda *a: None)
    assert verdicts["serial"] == verdicts["pool"] == verdicts["dask"]
    assert verdicts["serial"]["simulations"]["reduced"] == 40


def test_a_spurious_counterexample_corrects_the_search(tmp_path, monkeypatch):
    """A truth plant 15 mrad more forgiving than the reduced one (a planted model error):
    the first reduced-plant counterexample is refuted (spurious), the correction learns
    the offset, and the search goes on to a point the truth plant does fail."""
    from validation.batch.executor import SerialRunner
    from validation.verdicts import falsify, verify
    offset = 0.015
    original = falsify.effective_rho

    def forgiving(row, requirement):
        rho = original(row, requirement)
        return rho + offset if row.plant == "exudyn" and rho is not None else rho

    monkeypatch.setattr(falsify, "effective_rho", forgiving)
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM)
    (system,) = load_systems(path)
    v = verify.falsify(system, system.requirements[0], tmp_path / "out", runner=SerialRunner(),
                       budget=10, seed=0, log=lambda *a: None)
    assert v["spurious"], "the planted model error was never caught"
    assert all(s["rho_reduced"] < 0 <= s["rho_truth"] for s in v["spurious"])
    assert v["found"] and v["rho_truth"] < 0
    # confirmed only where the reduced plant says it fails by more than the offset
    assert v["rho_reduced"] < -offset


def test_a_counterexample_that_changes_sign_under_refinement_is_undecided(tmp_path,
                                                                          monkeypatch):
    """Known bad: every truth-plant point the search confirms fails on its own mesh but
    holds on the refined meshes (a planted discretisation error: +30 mrad on the checks).
    Such a point is no counterexample at this resolution: the search goes on, and ends
    with none found, the points "undecided at this resolution" with ρ on every level."""
    from validation.batch.executor import SerialRunner
    from validation.verdicts import falsify
    from validation.verdicts.mesh import is_check
    original = falsify.effective_rho

    def refined_away(row, requirement):
        rho = original(row, requirement)
        return rho + 0.03 if is_check(row) and rho is not None and rho > -1 else rho

    monkeypatch.setattr(falsify, "effective_rho", refined_away)
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM)
    (system,) = load_systems(path)
    v = falsify.falsify(system, system.requirements[0], tmp_path / "out",
                        runner=SerialRunner(), budget=2, seed=0, log=lambda *a: None)
    assert not v["found"] and v["verdict"] == "undecided at this resolution"
    assert v["counterexample"] is None and v["worst_case"] == "worst-case.toml"
    assert v["undecided"] and all(u["rho_truth"] < 0 for u in v["undecided"])
    assert {u["convergence"]["verdict"] for u in v["undecided"]} == {
        "undecided at this resolution"}
    assert v["convergence"]["verdict"] == "undecided at this resolution"
