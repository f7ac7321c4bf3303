"""Calibration (``flexarm calibrate``): parameters recovered from data the toolkit made
at stated values, intervals that cover the truth as often as they say, parameters the
data cannot see flagged, and bad data refused in one line before anything is written.

Data are made by the closed loop itself (the PBC fed the true state, eq. 37), so the
truth is known exactly; every fit starts away from it.  Simulations run in this process
(`SerialRunner`), stored in a temporary results folder like any calibration's.
"""
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from cli_testing import flexarm
from validation import cli, run_scenario, scenario_from_mapping
from validation.batch.executor import SerialRunner
from validation.run.config import ConfigError
from validation.run.experiments import from_run, read_experiment, write_experiment
from validation.run.tomlfiles import load_toml
from validation.verdicts.calibration import (calibrate, calibration_settings, linear_response,
                                            plan_calibration)
from validation.verdicts.calibration.intervals import parameter_uncertainty

NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}  # campaigns/base.toml
EI_MP = ["true_params.EI1", "true_params.EI2", "true_params.Mp"]
TRUTH = {"true_params.EI1": 10.0, "true_params.EI2": 10.0, "true_params.Mp": 0.1}


def experiment(plant="reduced", duration=1.0, seed=0, noise=None, params=None, name="e1",
               **extra):
    """A closed-loop run of the default arm (``params`` changed) as an experiment, its
    signals rounded to float32 as the store keeps them."""
    data = {"duration": duration, "plant": {"kind": plant}, "seed": seed,
            "sensors": dict(noise or {}), "true_params": dict(params or {}),
            "nominal_params": dict(params or {}), **extra}
    result = run_scenario(scenario_from_mapping(data))
    result.signals = result.signals.astype(np.float32)
    return from_run(result, name, f"<{name}>")


def model(plant="reduced", start=None, noise=NOISE, **extra):
    """The scenario a fit starts from: the default arm with ``start`` values, the
    campaigns' noise levels as the weights."""
    return scenario_from_mapping({"plant": {"kind": plant}, "sensors": dict(noise),
                                  "true_params": dict(start or {}), **extra})


def fit(tmp_path, base, names, experiments, *, table=None, responses=(), search=False,
        **options):
    """Calibrate ``names`` of ``base`` on ``experiments`` into tmp_path/out (without the
    search for missing physics unless ``search``: the tests of it ask for it)."""
    settings = calibration_settings(dict(table or {}), names, base)
    plan = plan_calibration(base, settings, [(e, None) for e in experiments], list(responses))
    return calibrate(plan, tmp_path / "out", runner=SerialRunner(), log=lambda *_: None,
                     search=search, **options)


def relative_errors(result, truth):
    return {n: abs(result["parameters"][n]["estimate"] - v) / v for n, v in truth.items()}


# --- recovery -----------------------------------------------------------------------------------
# The reduced plant in make test; the truth plant (13 s) in make test-all.
@pytest.mark.parametrize("plant", ["reduced", pytest.param("exudyn", marks=pytest.mark.slow)])
def test_noise_free_data_recover_every_parameter(tmp_path, plant):
    """1 s of noise-free data, starts 20-50 % off: every parameter within 0.5 % (the
    issue's bound; measured 1e-9 to 7e-8 on both plants, with residuals of 7e-4 and 5e-4
    of the noise levels: the float32 storage of the signals is the floor).  The known-bad
    case of the same bound is the next test."""
    data = experiment(plant)
    start = {"EI1": 12.0, "EI2": 8.0, "Mp": 0.15}
    result = fit(tmp_path, model(plant, start), EI_MP, [data])
    errors = relative_errors(result, TRUTH)
    assert max(errors.values()) <= 5e-3, errors
    assert all(p["identifiable"] for p in result["parameters"].values())
    # what calibration.json holds, as the issue names the keys
    stored = json.loads((tmp_path / "out" / "calibration.json").read_text())
    for key in ("parameters", "correlation", "residual_rms", "cost", "iterations", "simulations"):
        assert key in stored
    for p in stored["parameters"].values():
        assert set(p) >= {"estimate", "std", "ci95", "interval", "identifiable"}
    assert stored["model_adequate"] is True  # noise-free: white, below the stated noise


def test_a_wrong_fixed_parameter_biases_the_fit_beyond_the_bound(tmp_path):
    """Known-bad: the same data, the payload's inertia Jp wrong by 4x and not fitted:
    the stiffnesses absorb it (measured EI2 +7.3 %, far beyond 0.5 %), and the residuals
    show it (measured 43x the modal noise on q11, 11x the encoder noise on theta2, where
    the fit above leaves 7e-4 of them)."""
    data = experiment("reduced")
    result = fit(tmp_path, model("reduced", {"EI1": 12.0, "EI2": 8.0, "Jp": 0.002}),
                 ["true_params.EI1", "true_params.EI2"], [data], table={})
    errors = relative_errors(result, {"true_params.EI2": 10.0})
    assert errors["true_params.EI2"] > 5e-3, errors
    assert result["residual_rms"]["e1"]["q11"]["rms"] > 10 * 1e-5
    assert result["model_adequate"] is False  # and the residual tests say so


# --- intervals ------------------------------------------------------------------------------------
def coverage(tmp_path, seeds, start, names, truth, **model_extra):
    """How many of the seeds' intervals cover each true value; how many of their 95 %
    intervals of the noise alone (estimate ± t·std) do; how many fits are adequate."""
    covered = {n: 0 for n in names}
    noise_only = {n: 0 for n in names}
    adequate = 0
    for seed in seeds:
        data = experiment("reduced", duration=0.5, seed=seed, noise=NOISE)
        result = fit(tmp_path / str(seed), model("reduced", start, **model_extra), names, [data],
                     table={"horizon": 0.5})
        adequate += result["model_adequate"] is True
        for n in names:
            p = result["parameters"][n]
            lo, hi = p["interval"]
            covered[n] += lo <= truth[n] <= hi
            noise_only[n] += abs(p["estimate"] - truth[n]) <= 1.96 * p["std"]
    return covered, noise_only, adequate


@pytest.mark.slow
def test_95_percent_intervals_cover_the_truth_17_to_20_times_in_20(tmp_path):
    """20 noise seeds of the campaigns' sensor noise: each 95 % interval covers the true
    value in 17-20 of 20 (the issue's band: P(X >= 17) = 0.98 for X ~ B(20, 0.95), so a
    correct interval fails this one time in 50 per parameter; the seeds are fixed, so
    this outcome is too: measured 20, 20, 20; the standardised errors of 60 other seeds
    have standard deviations 0.93, 0.87, 0.86 against the 1 a correct interval implies).
    The model is adequate on at least 18 seeds (the residual tests' family false-alarm
    rate is 0.01: P(X <= 17) < 1e-3 for X ~ B(20, 0.99))."""
    covered, _, adequate = coverage(tmp_path, range(20), {"EI1": 10.5, "EI2": 9.5, "Mp": 0.105},
                                    EI_MP, TRUTH)
    assert all(17 <= c <= 20 for c in covered.values()), covered
    assert adequate >= 18, adequate


@pytest.mark.slow
def test_a_wrong_model_is_flagged_and_its_intervals_admit_it(tmp_path):
    """Known-bad: the payload inertia Jp 4x its true value and not fitted.  Intervals of
    the noise alone stay as narrow as the noise allows, around a biased estimate: EI2's
    covers the truth in far fewer than 17 of 20 (measured 0).  The residual tests flag
    the model on every seed, and the intervals it reports — effective parameters, the
    model error's share included — cover EI2 on every seed."""
    names = ["true_params.EI1", "true_params.EI2"]
    covered, noise_only, adequate = coverage(tmp_path, range(20), {"EI1": 10.5, "EI2": 9.5,
                                                                   "Jp": 0.002}, names, TRUTH)
    assert noise_only["true_params.EI2"] < 17, noise_only
    assert adequate == 0
    assert covered["true_params.EI2"] == 20, covered


# --- identifiability --------------------------------------------------------------------------------
def test_uncertainty_names_the_directions_the_jacobian_cannot_see():
    """Unit cases of the statistics: two identical columns (only their sum is seen), a
    zero column (not seen at all), a well-conditioned pair (both identifiable, std equal
    to the textbook s sqrt((J^T J)^-1))."""
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal(200), rng.standard_normal(200)
    r = rng.standard_normal(200)
    names = ["p.a", "p.b", "p.c"]
    J = np.column_stack([a, a, np.zeros(200)])
    out = parameter_uncertainty(J, r, names, np.ones(3), np.ones(3))
    assert not any(p["identifiable"] for p in out["parameters"].values())
    assert "+0.707 p.a" in out["parameters"]["p.a"]["reason"].replace("-", "+")
    assert "+1 p.c" in out["parameters"]["p.c"]["reason"]
    J = np.column_stack([a, b])
    out = parameter_uncertainty(J, r, names[:2], np.array([2.0, 3.0]), np.array([2.0, 3.0]))
    s2 = r @ r / 198
    expected = np.sqrt(np.diag(s2 * np.linalg.inv(J.T @ J))) * [2.0, 3.0]
    got = [out["parameters"][n]["std"] for n in names[:2]]
    np.testing.assert_allclose(got, expected, rtol=1e-12)  # the same formula, two ways
    assert all(p["identifiable"] for p in out["parameters"].values())


def test_parameters_the_data_see_together_or_not_at_all_are_flagged(tmp_path):
    """mh2 (the rotor) and stator_mass sit at the link-1 tip: the arm sees only their sum;
    mh1 sits on the fixed axis: the arm does not see it.  Both flagged with the singular
    direction named; EI1 in the same fit stays identifiable.  Known-good: fitting mh2
    alone (stator_mass known) recovers it, identifiable."""
    params = {"stator_mass": 0.5}
    data = experiment("reduced", duration=0.5, params=params)
    start = {"mh2": 1.3, "stator_mass": 0.4, "mh1": 1.5, "EI1": 11.0}
    names = ["true_params.mh2", "true_params.stator_mass", "true_params.mh1", "true_params.EI1"]
    # the sensors' modal basis is the nominal model's: the experiment's own
    result = fit(tmp_path / "all", model("reduced", start, nominal_params=params), names,
                 [data], table={"horizon": 0.5})
    p = result["parameters"]
    assert not p["true_params.mh2"]["identifiable"] and p["true_params.mh2"]["std"] is None
    assert not p["true_params.stator_mass"]["identifiable"]
    assert "mh2" in p["true_params.stator_mass"]["reason"]
    assert "+1 mh2 -1 stator_mass" in p["true_params.mh2"]["reason"].replace("−", "-") or \
        "-1 mh2 +1 stator_mass" in p["true_params.mh2"]["reason"]
    assert not p["true_params.mh1"]["identifiable"] and "mh1" in p["true_params.mh1"]["reason"]
    assert p["true_params.EI1"]["identifiable"]
    # the terminal's line is the short reason (issue 58: they ran to 1,000 characters)
    assert all(len(p[n]["why"]) <= 120 and p[n]["why"] for n in names[:3]), \
        [p[n]["why"] for n in names[:3]]
    assert "mh2" in p["true_params.stator_mass"]["why"]
    # their sum is what the data fixed: 1.0 + 0.5 (float32 data, noise-free: 1e-5)
    total = p["true_params.mh2"]["estimate"] + p["true_params.stator_mass"]["estimate"]
    assert abs(total - 1.5) < 1e-4
    one = fit(tmp_path / "one", model("reduced", {"mh2": 1.2, "stator_mass": 0.5},
                                      nominal_params=params),
              ["true_params.mh2"], [data], table={"horizon": 0.5})
    q = one["parameters"]["true_params.mh2"]
    assert q["identifiable"] and abs(q["estimate"] - 1.0) <= 5e-3 * 1.0


# --- the reduced model as the fitted plant ----------------------------------------------------------
@pytest.mark.slow
def test_a_reduced_model_fit_of_truth_data_differs_where_the_model_is_wrong(tmp_path):
    """The same 1 s of noise-free truth-plant data fitted with the truth plant and with the
    reduced model (2+2 modes, the paper's).  The truth-plant fit recovers the arm (within
    0.5 %) and leaves residuals below the noise levels.
    The reduced fit recovers its own parameters (`test_noise_free_data_recover_every_
    parameter[reduced]`), but here it moves them: measured EI1 +2.0 %, EI2 +12 %, Mp +35 %,
    and leaves residuals of 70x the encoder noise on theta1 and 200x the modal noise on
    q11.  Not modal truncation: 4+4 modes fit the same to 0.1 % (EI2 +12.3 %, Mp +35 %);
    replaying the same torques at the same parameters, the two plants part by 3.2 mrad
    in theta1 after 1 s, with tip deflections of up to 84 mm.  Bounds: 5 % (well clear
    of the measured 35 % and of the 0.5 % the truth-plant fit holds) and 10x the noise."""
    data = experiment("exudyn", duration=1.0)
    start = {"EI1": 11.0, "EI2": 9.0, "Mp": 0.12}
    truth_fit = fit(tmp_path / "truth", model("exudyn", start), EI_MP, [data])
    reduced_fit = fit(tmp_path / "reduced", model("reduced", start), EI_MP, [data])
    e_truth, e_reduced = (relative_errors(f, TRUTH) for f in (truth_fit, reduced_fit))
    assert max(e_truth.values()) <= 5e-3, e_truth
    assert max(e_reduced.values()) > 5e-2, e_reduced
    rms = lambda f: {s: v["rms"] / v["noise"] for s, v in f["residual_rms"]["e1"].items()}  # noqa: E731
    assert max(rms(truth_fit).values()) < 1.0
    assert rms(reduced_fit)["theta1"] > 10.0
    # the residual tests tell them apart: the truth plant's residual is white, below the
    # stated noise (noise-free data: "noise misstated"); the reduced model's is a model
    # error, and none of its intervals misses the arm
    assert truth_fit["model_adequate"] is True and reduced_fit["model_adequate"] is False
    for name, value in TRUTH.items():
        p = reduced_fit["parameters"][name]
        assert p["interval"] is None or p["interval"][0] <= value <= p["interval"][1], p


# --- frequency responses ------------------------------------------------------------------------------
@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
def test_frequency_responses_recover_the_stiffnesses(tmp_path, plant):
    """Responses of the linearised plant at the true arm (0.5-40 Hz: the free arm's
    bending modes), no time simulation: EI1, EI2 from 30 % off to within 0.5 % (measured
    below 1e-6: the data are the model's own)."""
    from validation.run.experiments import FrequencyResponse
    truth = model(plant)
    f = np.geomspace(0.5, 40.0, 60)
    pairs = (("theta1", "tau1"), ("theta2", "tau2"), ("q11", "tau1"), ("q21", "tau2"))
    values = linear_response(truth, (0.0, 0.0), f, pairs)
    response = FrequencyResponse("frf", "<frf>", f, pairs, values)
    result = fit(tmp_path, model(plant, {"EI1": 13.0, "EI2": 7.0}),
                 ["true_params.EI1", "true_params.EI2"], [], responses=[response])
    errors = relative_errors(result, {"true_params.EI1": 10.0, "true_params.EI2": 10.0})
    assert max(errors.values()) <= 5e-3, errors
    assert result["simulations"] == 0


# --- stored like runs; what it writes --------------------------------------------------------------
def test_a_rerun_replays_the_stored_simulations(tmp_path):
    """The same calibration again into the same folder simulates nothing new and gives
    the same numbers (the fit is a deterministic function of the stored values)."""
    data = experiment("reduced", duration=0.3)
    base = model("reduced", {"EI1": 11.0})
    first = fit(tmp_path, base, ["true_params.EI1"], [data])
    from validation.batch.store.folder import ResultStore
    count = len(ResultStore(tmp_path / "out").rows())
    again = fit(tmp_path, base, ["true_params.EI1"], [data])
    assert len(ResultStore(tmp_path / "out").rows()) == count == first["simulations"]
    assert again["parameters"] == first["parameters"]


def test_the_command_writes_a_runnable_scenario_and_a_verify_set(tmp_path, capsys,
                                                                  monkeypatch):
    """flexarm export --signals, then flexarm calibrate of the CSV: calibrated.toml runs,
    uncertainty.toml is a set flexarm verify accepts."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm.toml").write_text(
        'duration = 0.3\n[sensors]\nencoder_noise = 1e-4\nmodal_noise = 1e-5\n'
        'rate_noise = 1e-3\n')
    assert cli.main(["run", "--config", "arm.toml", "--out", "runs"]) == 0
    rid = next((tmp_path / "runs" / "runs").glob("*.npz")).stem
    assert cli.main(["export", "--signals", f"runs/{rid}", "--to", "e1.csv"]) == 0
    (tmp_path / "model.toml").write_text(
        'include = "arm.toml"\nname = "my-arm"\n[true_params]\nEI1 = 11.0\n[calibrate]\n'
        'fit = ["true_params.EI1", "true_params.Mp"]\n')
    # the CSV and the stored run it came from: two experiments of the same run
    assert cli.main(["calibrate", "e1.csv", f"runs/{rid}", "--config", "model.toml", "--out",
                     "cal", "--workers", "1", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "true_params.EI1" in out and f"residual RMS / noise, {rid}" in out
    assert '"model_adequate": true' in out
    # what to do with it (issue 58: nothing said so)
    assert "next: flexarm run --config cal/calibrated.toml" in out
    assert 'include = ["cal/calibrated.toml", "cal/uncertainty.toml"]' in out
    calibrated = load_toml(tmp_path / "cal" / "calibrated.toml")
    scenario_from_mapping(calibrated)  # flexarm run --config takes it
    assert calibrated["name"] == "my-arm"  # the config's (issue 47: it was "paper")
    (tmp_path / "verify.toml").write_text(
        'include = ["cal/calibrated.toml", "cal/uncertainty.toml"]\n'
        '[[requirement]]\nname = "tracking"\nclaim = "tracking"\n')
    from validation.verdicts.uncertainty import load_systems
    system, = load_systems(tmp_path / "verify.toml")
    assert {p for a in system.uncertainty.axes for p in a.paths} == {"true_params.EI1",
                                                                     "true_params.Mp"}
    # the report: a section of its own, the simulations not listed as runs
    assert cli.main(["report", "cal", "--no-animation", "--no-progress"]) == 0
    report = (tmp_path / "cal" / "report" / "report.md").read_text()
    assert "## Calibration" in report and "measured and fitted signals" in report
    assert "**The model: model adequate" in report and "Ljung–Box" in report
    assert "calibrate/" not in report
    # Issue 47: not a verify report, no "0 runs" and no empty bullets; its bottom line
    # first, computed from calibration.json.
    assert "verify" not in report.split("## Calibration")[0]
    assert "0 runs" not in report and not re.search(r"^- [\w ]+: *$", report, flags=re.M)
    assert report.split("\n\n")[1].startswith("**flexarm calibrate fitted true_params.EI1 = ")
    assert "The verdict on the model: model adequate" in report.split("\n\n")[1]


def test_export_signals_reads_back_exactly(tmp_path):
    """A run written as an experiment CSV reads back to the same float32 values."""
    exp = experiment("reduced", duration=0.05, noise=NOISE)
    path = tmp_path / "e.csv"
    with path.open("w") as fh:
        write_experiment(exp, fh, "synthetic\nsecond line")
    back = read_experiment(path)
    assert back.names == exp.names and back.Ts == pytest.approx(exp.Ts, rel=1e-12)
    np.testing.assert_array_equal(back.signals.astype(np.float32), exp.signals.astype(np.float32))
    np.testing.assert_array_equal(back.torques.astype(np.float32), exp.torques.astype(np.float32))


def test_the_replay_law_reproduces_the_closed_loop_bit_for_bit(tmp_path):
    """The recorded torques replayed open loop give the closed loop's measurements exactly
    (reduced plant, compiled loop): the fit's model of an experiment adds nothing."""
    from controllers._replay import file_sha256
    base = {"duration": 0.5, "controller": {"kind": "pbc"}}
    closed = run_scenario(scenario_from_mapping(base))
    np.save(tmp_path / "tau.npy", np.column_stack([closed["tau1"], closed["tau2"]]))
    replay = run_scenario(scenario_from_mapping(dict(base, controller={
        "kind": "replay", "options": {"file": str(tmp_path / "tau.npy"),
                                      "sha256": file_sha256(tmp_path / "tau.npy")}})))
    np.testing.assert_array_equal(replay.select(["y_theta1", "y_q11"]),
                                  closed.select(["y_theta1", "y_q11"]))
    (tmp_path / "tau.npy").write_bytes((tmp_path / "tau.npy").read_bytes()[:-8] + bytes(8))
    with pytest.raises(ConfigError, match="SHA-256"):  # changed after the fact: refused
        scenario_from_mapping(dict(base, controller={"kind": "replay", "options": {
            "file": str(tmp_path / "tau.npy"), "sha256": "0" * 64}}))


# --- failed simulations --------------------------------------------------------------------------
#: Plug-ins that fail: the reduced plant stepped from Python, its solver giving up in the
#: first step when EI1 > LIMIT (always, partly: beyond the fit's first steps, at the
#: edge: within the refinement's steps of the estimate, EI1 = 10), and a law that raises.
FAILING = {"faillab.py": '''
from reduced_model import PlantFailure, ReducedPlant


class Always(ReducedPlant):
    role = "reduced"
    LIMIT = -1.0

    def __init__(self, params, *, model, sensors, Ts):
        super().__init__(params, model=model, sensors=sensors, Ts=Ts)
        self.fails = params.EI1 > self.LIMIT

    def compiled(self):
        return None  # stepped from Python: _advance below

    def _advance(self, tau, tip_force):
        if self.fails:
            raise PlantFailure("the lab's solver lost the arm")
        super()._advance(tau, tip_force)


class Partly(Always):
    LIMIT = 10.005  # the fit's forward steps (1e-3: 10.01) fail, its refinement's do not


class Edge(Always):
    LIMIT = 10.00005  # the refinement's steps (±1.6e-4 of EI1) fail too


class Raising:
    name = "mypd"

    def __init__(self, model, *, Ts):
        pass

    def __call__(self, t, x, ref):
        raise RuntimeError("gain table missing")
'''}


def calibrate_failing(tmp_path, plugin_lab, table: str, start: float) -> tuple:
    """``flexarm calibrate`` of EI1 from ``start`` on 0.3 s of the default arm's data with
    the scenario's ``table`` (a failing plug-in); (status, stdout, stderr, out)."""
    plugin_lab(FAILING)
    data = experiment("reduced", duration=0.3, noise=NOISE)
    with (tmp_path / "e1.csv").open("w") as fh:
        write_experiment(data, fh, "the default arm, 0.3 s")
    sensors = "".join(f"{k} = {v}\n" for k, v in NOISE.items())
    (tmp_path / "m.toml").write_text(f"{table}\n[sensors]\n{sensors}[true_params]\nEI1 = "
                                     f"{start}\n[calibrate]\nfit = [\"true_params.EI1\"]\n"
                                     + ("inputs = \"closed-loop\"\n" if "controller" in table
                                        else ""))
    proc = flexarm(tmp_path, "calibrate", "e1.csv", "--config", "m.toml", "--out", "out",
                   "--workers", "1", "--no-progress")
    return proc.returncode, proc.stdout, proc.stderr, tmp_path / "out"


@pytest.mark.parametrize("table, reason", [
    ('[plant]\nkind = "faillab:Always"\nrole = "reduced"',
     "failed after 0.001 of 0.1 s: the lab's solver lost the arm"),
    ('[controller]\nkind = "faillab:Raising"',
     "failed after 0 of 0.1 s: mypd raised RuntimeError: gain table missing at t = 0 s"),
])
def test_a_calibration_whose_simulations_all_fail_is_refused_in_one_line(
        tmp_path, plugin_lab, table, reason):
    """Known bad: a plant that fails in every step, a law that raises.  Before, the fit
    returned its start, called the model adequate ("noise misstated") and wrote
    calibrated.toml.  Now: one line, every simulation failed with the first one's time and
    message, exit 1 (a failed computation, not bad input), no verdict, no result file."""
    status, out, err, folder = calibrate_failing(tmp_path, plugin_lab, table, 11.0)
    assert status == 1 and err.count("\n") == 1, err
    assert err.startswith("flexarm: error: the fit could not be computed: every simulation "
                          "failed (") and reason in err, err
    assert "adequate" not in out + err and "model_adequate" not in out
    for name in ("calibration.json", "calibrated.toml", "uncertainty.toml"):
        assert not (folder / name).exists()
    assert (folder / "runs").is_dir()  # the simulations stay, as runs


def test_failed_trial_points_are_rejected_and_the_result_rests_on_none(tmp_path, plugin_lab):
    """Known good: simulations beyond EI1 = 10.005 fail — the fit's steps from 9.5 cross
    it, the refinement at the estimate (steps of ±1.6e-4) does not.  The failed trial
    points are rejected, the estimate and its interval are those of the arm's own data
    (measured: 10.000001 ± 1.5e-5, the same as a plant that never fails), the failures
    are named, and the status is 1."""
    status, out, err, folder = calibrate_failing(
        tmp_path, plugin_lab, '[plant]\nkind = "faillab:Partly"\nrole = "reduced"', 9.5)
    assert status == 1 and "the estimate and its intervals rest on none of them" in err, err
    result = json.loads((folder / "calibration.json").read_text())
    ei1 = result["parameters"]["true_params.EI1"]
    assert result["failed_runs"] and ei1["jacobian"]["settled"]
    # the interval covers the truth, at the width of the noise (a penalty read as a slope
    # gave 5.4e-9 in the known-bad case below): 1e-6 sits 15× below the measured 1.5e-5
    assert ei1["interval"][0] < 10.0 < ei1["interval"][1] and ei1["std"] > 1e-6
    assert (folder / "calibrated.toml").is_file()


def test_a_result_resting_on_a_failed_simulation_is_refused(tmp_path, plugin_lab):
    """Known bad for the rule above: simulations beyond EI1 = 10.00005 fail, within the
    refinement's steps of the estimate.  Before, a failed step's penalty read as a slope:
    EI1 = 10.000001 ± 5.4e-9, its 95 % interval excluding the arm's 10, "model adequate",
    uncertainty.toml written.  Now the fit is refused in one line naming the Jacobian."""
    status, out, err, folder = calibrate_failing(
        tmp_path, plugin_lab, '[plant]\nkind = "faillab:Edge"\nrole = "reduced"', 9.5)
    assert status == 1 and err.count("\n") == 1, err
    assert "the fit could not be computed: the Jacobian of its intervals rests on " \
           "simulations that failed" in err and "the lab's solver lost the arm" in err
    assert "adequate" not in out + err
    assert not (folder / "calibrated.toml").exists() and not (folder / "uncertainty.toml").exists()


# --- bad input ------------------------------------------------------------------------------------
GOOD = "t,tau1,tau2,theta1,theta2\n0,0.1,0.0,0.0,0.0\n0.001,0.1,0.0,1e-6,0.0\n0.002,0.1,0.0,4e-6,0.0\n"


@pytest.mark.parametrize("text, column, words", [
    ("t,tau1,theta1,theta2\n0,0.1,0.0,0.0\n0.001,0.1,1e-6,0.0\n", "tau2", "missing"),
    (GOOD.replace("0.002,", "0.0005,"), "t", "does not increase"),
    (GOOD.replace("4e-6", "nan"), "theta1", "not finite"),
    (GOOD.replace("4e-6", "abc"), "theta1", "not a number"),
    (GOOD.replace("4e-6,0.0", "4e-6,114.6"), "theta2", "not in rad"),
    (GOOD.replace("0.001,", "1,").replace("0.002,", "2,"), "t", "not the scenario's Ts"),
    ("t,tau1,tau2,theta1\n0,0.1,0.0,0.0\n", "t", "at least two"),
    (GOOD.replace("theta2", "theta9"), "theta9", "not a measurement"),
    (GOOD.replace("0.002,", "0.0025,"), "t", "not constant"),
])
def test_bad_data_is_one_line_naming_file_and_column_exit_2_nothing_written(
        tmp_path, capsys, text, column, words):
    """Known-bad files, one defect each; the good file passes the same checks (below)."""
    (tmp_path / "m.toml").write_text("[calibrate]\nfit = [\"true_params.EI1\"]\n")
    (tmp_path / "bad.csv").write_text(text)
    status = cli.main(["calibrate", str(tmp_path / "bad.csv"), "--config",
                       str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and err.startswith("flexarm: error: ")
    assert f"bad.csv: column {column}" in err and words in err, err
    assert not (tmp_path / "out").exists()


def test_the_good_file_of_the_bad_cases_passes(tmp_path):
    (tmp_path / "good.csv").write_text(GOOD)
    base = model()
    settings = calibration_settings({}, ["true_params.EI1"], base)
    exp = read_experiment(tmp_path / "good.csv")
    plan = plan_calibration(base, settings, [(exp, None)])
    assert plan.targets[0].experiment.samples == 3


@pytest.mark.parametrize("fit_names, table, key", [
    ("true_params.L1", "", "--fit true_params.L1"),
    ("true_params.EI9", "", "--fit true_params.EI9"),
    ("sensors.delay", "", "--fit sensors.delay"),
    ("true_params.EI1", "bounds = { \"true_params.EI1\" = [20.0, 30.0] }", "calibrate.start"),
    ("true_params.EI1", "colour = 1", "calibrate.colour"),
    ("true_params.EI1", "inputs = \"guess\"", "calibrate.inputs"),
])
def test_bad_settings_name_their_key(tmp_path, capsys, fit_names, table, key):
    (tmp_path / "m.toml").write_text(f"[calibrate]\n{table}\n")
    (tmp_path / "good.csv").write_text(GOOD)
    status = cli.main(["calibrate", str(tmp_path / "good.csv"), "--config",
                       str(tmp_path / "m.toml"), "--fit", fit_names, "--out",
                       str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and f"flexarm: error: {key}" in err, err
    assert not (tmp_path / "out").exists()


def test_settings_of_an_experiment_not_given_name_the_file_to_pass(tmp_path, capsys):
    """Issue 47: the README's line passed tracking.csv alone while arm.toml has settings
    for "moving": the error names moving.csv beside it (known-bad: it said only "no
    experiment of that name"); with no such file, it says what to pass."""
    (tmp_path / "m.toml").write_text('[calibrate]\nfit = ["true_params.EI1"]\n'
                                     '[calibrate.experiment.moving]\n'
                                     'initial_state = "reference"\n')
    (tmp_path / "good.csv").write_text(GOOD)
    args = ["calibrate", str(tmp_path / "good.csv"), "--config", str(tmp_path / "m.toml"),
            "--out", str(tmp_path / "out")]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("flexarm: error: calibrate.experiment.moving: ") and \
        f"given: good ({tmp_path / 'good.csv'})" in err and "(moving.csv, or a stored " \
        "run RESULTS/moving)" in err, err
    (tmp_path / "moving.csv").write_text(GOOD)
    assert cli.main(args) == 2
    assert f"pass {tmp_path / 'moving.csv'} too" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_scenario_file_with_calibrate_still_runs(tmp_path):
    """[calibrate] is a section of a scenario file, not a scenario key: the other commands
    read the file as they did."""
    from validation.batch.campaign import load_study
    (tmp_path / "s.toml").write_text("duration = 1.0\n[calibrate]\nfit = [\"true_params.EI1\"]\n")
    study = load_study(tmp_path / "s.toml")
    assert study.calibrate == {"fit": ["true_params.EI1"]}
    assert scenario_from_mapping(study.base).duration == 1.0
    assert math.isfinite(study.base["duration"])


# --- the shipped example ---------------------------------------------------------------------------
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "calibration"


def test_the_shipped_example_is_labelled_small_and_plans():
    """Every data file says it is synthetic, the set stays small (issue: a few hundred
    KB; four files of 5-142 KB), and its files pass every check of a calibration, the
    friction experiment with its own arm (friction.toml)."""
    from validation.run.experiments import read_frequency_response
    from validation.verdicts.calibration import base_scenario
    files = sorted(EXAMPLE.glob("*.csv"))
    assert {f.name for f in files} == {"tracking.csv", "moving.csv", "frf.csv",
                                       "reversals.csv"}
    assert sum(f.stat().st_size for f in files) < 500_000
    for f in files:
        assert f.read_text().startswith("# SYNTHETIC")
    base, table = base_scenario(EXAMPLE / "arm.toml")
    settings = calibration_settings(table, None, base)
    plan = plan_calibration(base, settings, [(read_experiment(EXAMPLE / f"{n}.csv"), None)
                                             for n in ("tracking", "moving")],
                            [read_frequency_response(EXAMPLE / "frf.csv")])
    moving = next(t for t in plan.targets if t.experiment.name == "moving")
    assert moving.scenario["initial_state"] == "reference"  # its own setting
    base, table = base_scenario(EXAMPLE / "friction.toml")
    settings = calibration_settings(table, None, base)
    assert "true_params.coulomb1" in settings.names
    plan_calibration(base, settings, [(read_experiment(EXAMPLE / "reversals.csv"), None)])


@pytest.mark.slow
def test_the_python_walk_through_recovers_the_stated_arm(tmp_path):
    """examples/calibration/calibrate.py as written (two workers): the stated parameters
    (EI1 9.2, EI2 10.6, Mp 0.23) within 0.5 %, each within 3 standard errors (measured
    +2.07, +1.18, +1.43: the example's fixed noise realisation puts EI1 just outside its
    95 % interval — one interval in twenty does — and the same data unrounded give the
    same, so it is the noise, not the 7 digits of the files)."""
    import os
    import runpy
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        runpy.run_path(str(EXAMPLE / "calibrate.py"), run_name="__main__")
    finally:
        os.chdir(cwd)
    result = json.loads((tmp_path / "results" / "calibrate-example" /
                         "calibration.json").read_text())
    truth = {"true_params.EI1": 9.2, "true_params.EI2": 10.6, "true_params.Mp": 0.23}
    assert max(relative_errors(result, truth).values()) <= 5e-3
    for name, value in truth.items():
        p = result["parameters"][name]
        assert abs(p["estimate"] - value) <= 3 * p["std"], (name, p)
