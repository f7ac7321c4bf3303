"""Calibration that knows when its model is wrong: the residual tests and their verdict,
honest intervals either way, and models compared on the same data.

Known-good: the inverse crime (data and fit from the same model) is adequate and its
95 % intervals cover.  Known-bad: the paper's reduced model fitted to FE data is flagged
inadequate, and no interval it reports misses the hidden value; a noise level stated 10×
too small is caught by the χ² test and called what it is, not a model error.  The unit
cases feed the tests residuals of known make-up.  Data are made by the toolkit's closed
loop (`test_calibration.experiment`), so the hidden values are known exactly.
"""
import json

import numpy as np
import pytest
import scipy.stats

from test_calibration import EI_MP, NOISE, TRUTH, experiment, fit, model
from validation.cli import main
from validation.verdicts.calibration.adequacy import FAMILY_ALPHA, Block, adequacy
from validation.verdicts.calibration.intervals import MODEL_ERROR_FACTOR, parameter_uncertainty

HIDDEN = {"EI1": 8.6, "EI2": 11.3, "Mp": 0.37}  # the lab arm
#: The FE arm the lab data come from in the slow cases (the issue's), and the cheap one.
LAB_MESH = {"element": "geometrically_exact", "elements_per_link": [16, 16]}


def lab_experiment(seed: int, duration: float):
    """The issue's lab: the geometrically exact FE arm (16 el/link) at the hidden values,
    an EKF-observed tracking run with a torque pulse, the campaigns' sensor noise."""
    from validation import run_scenario, scenario_from_mapping
    from validation.run.experiments import from_run
    result = run_scenario(scenario_from_mapping({
        "duration": duration, "seed": seed, "sensors": NOISE, "true_params": HIDDEN,
        "plant": {"kind": "exudyn", "mesh": LAB_MESH}, "observer": {"kind": "ekf"},
        "disturbances": [{"kind": "pulse", "target": "tau1", "amplitude": 2.0,
                          "start": 1.0, "duration": 0.1}]}))
    result.signals = result.signals.astype(np.float32)
    return from_run(result, "lab", "<lab>")


def reads_tenfold(test: dict) -> bool:
    """The white part's level reads noise 10× the stated: its statistic over 10 lies in
    the band the noise test accepts for the stated level (±3.5 standard deviations at
    500 samples: ±18 %; a level estimated from 500 samples of the fourth difference
    has a relative standard deviation of 1.15/√496 = 5 %)."""
    low, high = test["threshold"]
    return low <= test["statistic"] / 10 <= high


def covers(result, truth):
    """{name: True/False} whether each reported interval holds the hidden value (a
    parameter reported without interval, not identifiable, holds nothing false)."""
    out = {}
    for name, value in truth.items():
        p = result["parameters"][f"true_params.{name}"]
        out[name] = p["interval"] is None or p["interval"][0] <= value <= p["interval"][1]
    return out


# --- the tests on residuals of known make-up -------------------------------------------------
def blocks(residuals, torques):
    return [Block("e", f"s{i}", r, 1.0, 1.0, torques) for i, r in enumerate(residuals)]


@pytest.fixture(scope="module")
def torque():
    """A smooth tracking torque of 2000 samples, as the experiments have (two joints)."""
    t = np.arange(2000) * 1e-3
    return np.vstack([np.sin(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 3 * t),
                      0.5 * np.cos(2 * np.pi * 1.1 * t)])


def test_white_noise_at_the_stated_level_is_adequate(torque):
    rng = np.random.default_rng(1)
    v = adequacy(blocks(rng.standard_normal((6, 2000)), torque))
    assert v["model_adequate"] and v["noise_as_stated"] and not v["failing"]
    assert v["verdict"].startswith("model adequate: the residual is white noise")


def test_the_family_of_tests_falses_an_adequate_model_about_once_in_a_hundred(torque):
    """200 fits' worth of white residuals (6 signals each): the family's false alarms
    follow B(200, p ≤ 0.01) (Bonferroni is conservative): at most 8 — P(X ≥ 9) = 2e-4 at
    p = 0.01 — and the per-test level is 0.01 over the number of tests."""
    rng = np.random.default_rng(2)
    flagged = 0
    for _ in range(200):
        v = adequacy(blocks(rng.standard_normal((6, 2000)), torque))
        flagged += v["model_adequate"] is False or v["noise_as_stated"] is False
    assert flagged <= 8, flagged
    assert v["test_alpha"] == pytest.approx(FAMILY_ALPHA / 24)  # 6 signals x 4 tests


def test_noise_ten_times_the_stated_level_is_misstated_noise_not_model_error(torque):
    """χ² fails (variance 100×), whiteness and inputs pass: the model is adequate, the
    noise is misstated, and the white part's level says by how much (10 within 5 %)."""
    rng = np.random.default_rng(3)
    v = adequacy(blocks(10 * rng.standard_normal((6, 2000)), torque))
    assert v["model_adequate"] is True and v["noise_as_stated"] is False
    signal = v["signals"]["e"]["s0"]
    assert not signal["chi2"]["passed"] and signal["whiteness"]["passed"]
    assert signal["diagnosis"] == "noise"
    assert signal["noise"]["statistic"] == pytest.approx(10, rel=0.05)
    assert "noise misstated" in v["verdict"] and "not the model" in v["verdict"]


@pytest.mark.parametrize("error, failing", [
    ("slow", {"level"}),               # a smooth error: correlated, beyond the noise
    ("input", {"inputs"}),             # the torque's effect, delayed and filtered, missed
])
def test_a_model_error_is_called_one_and_the_noise_level_still_read(torque, error, failing):
    """A residual of noise at the stated level plus a model error: inadequate, the
    failing tests named, and the noise level read as stated (the fourth difference does
    not see the smooth error)."""
    rng = np.random.default_rng(4)
    noise = rng.standard_normal((6, 2000))
    t = np.arange(2000) * 1e-3
    if error == "slow":
        noise[2] += 5 * np.sin(2 * np.pi * 1.3 * t)
    else:
        lagged = np.concatenate([np.zeros(5), torque[0, :-5]])
        noise[2] += 0.5 * np.convolve(lagged, np.ones(30) / 30, mode="same")
    v = adequacy(blocks(noise, torque))
    tests = v["signals"]["e"]["s2"]
    assert v["model_adequate"] is False and tests["diagnosis"] == "model"
    assert failing <= {k for k in ("chi2", "level", "whiteness", "inputs")
                       if k in tests and not tests[k]["passed"]}
    assert v["noise_as_stated"] is True and "the noise levels are as stated" in v["verdict"]
    assert all(s["diagnosis"] == "adequate" for k, s in v["signals"]["e"].items() if k != "s2")


def test_the_model_error_interval_is_its_bound_by_hand():
    """An inadequate model's interval: the noise's t·s·sqrt((JᵀJ)⁻¹_ii) plus κ·‖e‖ times
    the same factor (the largest change of parameter i whose output change, after the
    other parameters' best compensation, is no larger than κ‖e‖: Cauchy–Schwarz); no 95 %
    interval is given (‖e‖ = 4: both directions stay determined to ±100 %)."""
    rng = np.random.default_rng(5)
    J = rng.standard_normal((300, 2))
    r = rng.standard_normal(300)
    out = parameter_uncertainty(J, r, ["p.a", "p.b"], np.array([2.0, 3.0]),
                                np.array([2.0, 3.0]), model_error=4.0, noise_variance=1.5)
    factor = np.sqrt(np.diag(np.linalg.inv(J.T @ J))) * [2.0, 3.0]
    t = scipy.stats.t.ppf(0.975, 298)
    for i, name in enumerate(["p.a", "p.b"]):
        p = out["parameters"][name]
        assert p["ci95"] is None and p["model_error"] == pytest.approx(
            MODEL_ERROR_FACTOR * 4.0 * factor[i], rel=1e-12)
        half = t * np.sqrt(1.5) * factor[i] + MODEL_ERROR_FACTOR * 4.0 * factor[i]
        assert p["interval"] == pytest.approx([p["estimate"] - half, p["estimate"] + half],
                                              rel=1e-12)
    assert out["interval_kind"].startswith("effective parameters")


# --- fits: the inverse crime, the wrong model, the wrong noise --------------------------------
def test_the_inverse_crime_is_adequate_and_covers(tmp_path):
    """Known-good: 0.5 s of the reduced plant with the campaigns' noise, fitted by it:
    adequate, noise as stated, 95 % intervals that cover (20 seeds: the slow test)."""
    data = experiment("reduced", duration=0.5, seed=7, noise=NOISE)
    result = fit(tmp_path, model("reduced", {"EI1": 10.5, "EI2": 9.5, "Mp": 0.105}), EI_MP,
                 [data], table={"horizon": 0.5})
    assert result["model_adequate"] is True and result["adequacy"]["noise_as_stated"] is True
    assert all(covers(result, {k.split(".")[1]: v for k, v in TRUTH.items()}).values())
    assert all(p["ci95"] == p["interval"] for p in result["parameters"].values())


def test_the_reduced_model_on_fe_data_is_inadequate_and_no_interval_misses(tmp_path):
    """Known-bad: 1 s of the FE arm (ANCF 4 el/link, the campaigns' noise) at the hidden
    values, fitted by the paper's reduced model: inadequate (its residual 2-470× the
    noise, correlated, following the torques), the estimates labelled effective, and
    every interval it reports holds the hidden value (measured: EI1 +3.3 % in an interval
    of −6.3..+13.0 %, −2.5..+9.1 % with κ = 3; EI2 +11 % and Mp +26 % reported not identifiable against the model
    error, with no interval).  Its ranges are not handed to verify: no uncertainty.toml
    (it was written before, labelled effective); asked for (export_inadequate, the same
    fit again from its stored runs), it is written with a warning and the label, and
    verify carries it onto its verdicts."""
    data = experiment("exudyn", duration=1.0, seed=1, noise=NOISE, params=HIDDEN)
    result = fit(tmp_path, model("reduced", {"EI1": 10.0, "EI2": 10.0, "Mp": 0.1},
                                 nominal_params=HIDDEN), EI_MP, [data])
    assert result["model_adequate"] is False
    assert "MODEL INADEQUATE" in result["adequacy"]["verdict"]
    assert "the noise levels are as stated" in result["adequacy"]["verdict"]
    assert all(covers(result, HIDDEN).values()), result["parameters"]
    assert all(p["ci95"] is None for p in result["parameters"].values())
    assert result["interval_kind"].startswith("effective parameters")
    assert not (tmp_path / "out" / "uncertainty.toml").exists() and not result["exported"]
    again = fit(tmp_path, model("reduced", {"EI1": 10.0, "EI2": 10.0, "Mp": 0.1},
                                nominal_params=HIDDEN), EI_MP, [data], export_inadequate=True)
    assert again["exported"] and again["parameters"] == result["parameters"]
    text = (tmp_path / "out" / "uncertainty.toml").read_text()
    assert "EFFECTIVE parameters" in text and 'calibration = "inadequate"' in text
    assert "WARNING: written by --export-inadequate" in text
    (tmp_path / "verify.toml").write_text(
        'include = ["out/calibrated.toml", "out/uncertainty.toml"]\n'
        '[[requirement]]\nname = "tracking"\nclaim = "tracking"\n')
    from validation.verdicts.uncertainty import load_systems
    system, = load_systems(tmp_path / "verify.toml")
    assert "CAVEAT" in system.uncertainty.describe()[-1]


def test_noise_stated_ten_times_too_small_is_caught_by_chi2_not_taken_for_model_error(tmp_path):
    """The inverse crime with every noise level stated 10× too small: χ² fails on every
    signal, the model stays adequate, and the verdict says the noise is misstated by
    10× (the white part reads it on every signal); the intervals use the residual's own
    level, so they still cover."""
    data = experiment("reduced", duration=0.5, seed=7, noise=NOISE)
    stated = {k: v / 10 for k, v in NOISE.items()}
    result = fit(tmp_path, model("reduced", {"EI1": 10.5, "EI2": 9.5, "Mp": 0.105},
                                 noise=stated), EI_MP, [data], table={"horizon": 0.5})
    verdict = result["adequacy"]
    assert result["model_adequate"] is True and verdict["noise_as_stated"] is False
    signals = verdict["signals"]["e1"]
    assert all(not s["chi2"]["passed"] for s in signals.values())
    assert all(reads_tenfold(s["noise"]) for s in signals.values())
    assert "noise misstated" in verdict["verdict"]
    assert all(covers(result, {k.split(".")[1]: v for k, v in TRUTH.items()}).values())


def test_a_closed_loop_fit_is_not_judged_and_says_so(tmp_path):
    """With the controller in the loop the simulation draws its own noise: the residual
    is not the measurement noise, the model is not judged (null), its intervals are
    those of effective parameters, and uncertainty.toml says "not judged"."""
    data = experiment("reduced", duration=0.3, seed=7, noise=NOISE)
    result = fit(tmp_path, model("reduced", {"EI1": 10.5}), ["true_params.EI1"], [data],
                 table={"inputs": "closed-loop"})
    assert result["model_adequate"] is None
    assert result["adequacy"]["verdict"].startswith("not judged")
    assert result["parameters"]["true_params.EI1"]["ci95"] is None
    assert 'calibration = "not judged"' in (tmp_path / "out" / "uncertainty.toml").read_text()


# --- which model explains the data -----------------------------------------------------------
def test_models_fitted_to_the_same_data_are_compared_in_one_table(tmp_path, capsys,
                                                                   monkeypatch):
    """FE data (0.5 s) fitted by the reduced model, then by the truth plant with
    --compare (both from 5-8 % off, the sensors' modal basis the experiment's, its
    controller's model — with another basis the truth plant's fit was flagged inadequate,
    rightly: its q are other coordinates): one table, the truth plant first (adequate, the lower AIC by far), the
    reduced model inadequate; in calibration.json and the report.  Known-bad: a fit of
    other data is refused by --compare before anything runs."""
    from validation.run.experiments import write_experiment
    monkeypatch.chdir(tmp_path)
    data = experiment("exudyn", duration=0.5, seed=2, noise=NOISE, params=HIDDEN)
    with open("lab.csv", "w") as fh:
        write_experiment(data, fh, "FE arm, hidden values")
    for plant in ("reduced", "exudyn"):
        (tmp_path / f"{plant}.toml").write_text(
            f'[plant]\nkind = "{plant}"\n[true_params]\nEI1 = 9.0\nEI2 = 11.0\nMp = 0.4\n'
            '[nominal_params]\nEI1 = 8.6\nEI2 = 11.3\nMp = 0.37\n'  # the data's sensor basis
            '[sensors]\nencoder_noise = 1e-4\n'
            'modal_noise = 1e-5\nrate_noise = 1e-3\n[calibrate]\n'
            'fit = ["true_params.EI1", "true_params.EI2", "true_params.Mp"]\n')
    common = ["--workers", "1", "--no-progress"]
    assert main(["calibrate", "lab.csv", "--config", "reduced.toml", "--out", "red",
                 "--no-search", *common]) == 0
    out = capsys.readouterr().out
    assert '"model_adequate": false' in out
    # what to do next (issue 58): the physics the screen points at, the search, --compare
    assert "next: the residual follows" in out and "without --no-search" in out, out
    assert not (tmp_path / "red" / "uncertainty.toml").exists()
    assert main(["calibrate", "lab.csv", "--config", "exudyn.toml", "--out", "fe",
                 "--compare", "red", *common]) == 0
    out = capsys.readouterr().out
    assert "which model explains the data" in out
    rows = json.loads((tmp_path / "fe" / "calibration.json").read_text())["comparison"]
    assert [r["folder"] for r in rows] == ["fe", "red"]
    assert rows[0]["model_adequate"] is True and rows[1]["model_adequate"] is False
    assert rows[1]["delta_aic"] > 1e3 and rows[0]["delta_aic"] == 0
    assert main(["report", "fe", "--no-animation", "--no-progress"]) == 0
    assert "Which model explains the data" in (tmp_path / "fe" / "report" /
                                               "report.md").read_text()
    # another experiment: not the same data
    other = experiment("exudyn", duration=0.5, seed=3, noise=NOISE, params=HIDDEN)
    with open("other.csv", "w") as fh:
        write_experiment(other, fh, "another run")
    assert main(["calibrate", "other.csv", "--config", "exudyn.toml", "--out", "fe2",
                 "--compare", "red", *common]) == 2
    assert "--compare" in capsys.readouterr().err and not (tmp_path / "fe2").exists()


# --- the expensive cases: 20 seeds --------------------------------------------------------------
@pytest.mark.slow
def test_the_reduced_model_on_ge_data_is_flagged_on_every_seed_and_never_misses(tmp_path):
    """The issue's lab: 2 s of the geometrically exact arm (16 el/link) at the hidden
    values, an EKF-observed tracking run with a torque pulse, 20 noise seeds; the
    reduced model flagged inadequate on every one, and no interval misses (measured on
    seed 0: EI1 8.25..9.29, EI2 and Mp not identifiable against the model error)."""
    for seed in range(20):
        data = lab_experiment(seed, duration=2.0)
        result = fit(tmp_path / str(seed), model("reduced"), EI_MP, [data])
        assert result["model_adequate"] is False, seed
        assert all(covers(result, HIDDEN).values()), (seed, result["parameters"])


@pytest.mark.slow
def test_noise_misstated_tenfold_is_caught_on_every_seed(tmp_path):
    """20 seeds of the inverse crime with the noise stated 10× too small: χ² fails on
    every seed; the model is called adequate on at least 18 (the family's false-alarm
    rate is 0.01: P(X ≤ 17) < 1e-3 for X ~ B(20, 0.99)); the white part reads 10×
    within 15 % on every signal."""
    adequate = 0
    stated = {k: v / 10 for k, v in NOISE.items()}
    for seed in range(20):
        data = experiment("reduced", duration=0.5, seed=seed, noise=NOISE)
        result = fit(tmp_path / str(seed), model("reduced", {"EI1": 10.5, "EI2": 9.5,
                                                             "Mp": 0.105}, noise=stated),
                     EI_MP, [data], table={"horizon": 0.5})
        signals = result["adequacy"]["signals"]["e1"].values()
        assert all(not s["chi2"]["passed"] for s in signals), seed
        assert all(reads_tenfold(s["noise"]) for s in signals), seed
        adequate += result["model_adequate"] is True
    assert adequate >= 18, adequate
