"""Calibration that tells coloured measurement noise from model error, and names the
physics an inadequate model lacks (issue 60); angles in degrees refused, and the next
step said (issue 58).

Data are made by the toolkit at stated values (the calibration examples' arm: joint-1
friction, a reference with velocity reversals), on the reduced plant where a fit is
cheap; the measurement noise is drawn separately, white or coloured, at the stated
levels.  Known-good: the right model.  Known-bad: a model without the physics the data
have, and the same search with that physics removed from the candidates.
"""
import math

import numpy as np
import pytest

from test_calibration import EXAMPLE, NOISE, fit
from test_calibration_adequacy import covers
from validation import cli, run_scenario, scenario_from_mapping
from validation.run.config import ConfigError
from validation.run.experiments import Experiment, from_run, read_experiment, write_experiment
from validation.verdicts.calibration import (base_scenario, calibration_settings,
                                             plan_calibration, workflow)
from validation.verdicts.calibration import extensions as extensions_room
from validation.verdicts.calibration.adequacy import Block, adequacy
from validation.verdicts.calibration.comparison import model_description
from validation.verdicts.calibration.intervals import parameter_uncertainty
from validation.verdicts.calibration.noise import fit_noise, sandwich_meat

TRUE = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23, "coulomb1": 0.25, "viscous1": 0.15}
START = {"EI1": 10.0, "EI2": 10.0, "Mp": 0.2, "coulomb1": 0.3, "viscous1": 0.2}
FITTED = [f"true_params.{n}" for n in TRUE]
REVERSALS = {"kind": "paper", "amplitude": [0.2, 0.2], "omega": [math.pi, 1.3 * math.pi]}
KEPT = ("theta1", "theta2", "q11", "q21")
LEVEL = np.array([1e-4, 1e-4, 1e-5, 1e-5])[:, None]
BOUNDS = {"bounds": {"true_params": {"Mp": [0.0, 2.0], "coulomb1": [0.0, 2.0],
                                     "viscous1": [0.0, 2.0]}}}


def data(extra=None, *, noise="white", seed=3, kinematics="linear", reference=REVERSALS,
         duration=2.0):
    """The arm at TRUE (and ``extra``) tracking ``reference`` on the reduced plant, fed
    its true state (so the torques do not depend on the noise), its kept signals with
    noise drawn here at the stated levels: white, or AR(1) of ρ = 0.9."""
    run = run_scenario(scenario_from_mapping({
        "duration": duration, **({"reference": reference} if reference else {}),
        "plant": {"kind": "reduced", "kinematics": kinematics},
        "true_params": {**TRUE, **(extra or {})}, "nominal_params": TRUE}))
    full = from_run(run, "e1", "<e1>")
    clean = full.signals[[full.names.index(n) for n in KEPT]]
    rng = np.random.default_rng(seed)
    w = rng.standard_normal(clean.shape)
    if noise == "ar1":
        for k in range(1, w.shape[1]):
            w[:, k] = 0.9 * w[:, k - 1] + math.sqrt(1 - 0.81) * w[:, k]
    return Experiment("e1", "<e1>", full.Ts, full.torques, KEPT,
                      (clean + LEVEL * w).astype(np.float32).astype(np.float64))


def start_model(kinematics="linear"):
    return scenario_from_mapping({"plant": {"kind": "reduced", "kinematics": kinematics},
                                  "sensors": NOISE, "reference": REVERSALS,
                                  "true_params": {**TRUE, **START}, "nominal_params": TRUE})


# --- units and the next step (issue 58) ----------------------------------------------------------
def test_angles_in_degrees_are_refused_in_one_line_before_anything_is_written(tmp_path,
                                                                               capsys):
    """The friction example's theta columns ×57.29578 (largest 9.7: below the 50 rad the
    reader refuses): one line naming the file and column, exit 2, nothing written.
    Known-good: the shipped experiments in radians plan (their measured ranges are
    0.88-1.21 of the start model's)."""
    source = read_experiment(EXAMPLE / "reversals.csv")
    rows = [i for i, n in enumerate(source.names) if n.startswith("theta")]
    signals = source.signals.copy()
    signals[rows] *= 180 / math.pi
    path = tmp_path / "deg.csv"
    with path.open("w") as fh:
        write_experiment(Experiment("deg", str(path), source.Ts, source.torques, source.names,
                                    signals), fh, "reversals.csv in degrees")
    status = cli.main(["calibrate", str(path), "--config", str(EXAMPLE / "friction.toml"),
                       "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert f"{path}: column theta1" in err and "in degrees?" in err
    assert not (tmp_path / "out").exists()
    base, table = base_scenario(EXAMPLE / "friction.toml")
    plan_calibration(base, calibration_settings(table, None, base), [(source, None)])


def test_fit_that_replaces_the_files_list_says_so():
    """``--fit true_params.coulomb1`` with arm.toml: the file's bounds name Mp, which
    the file fits and --fit does not: the error says --fit replaced the list, and how to
    fit both."""
    base, table = base_scenario(EXAMPLE / "arm.toml")
    with pytest.raises(ConfigError) as info:
        calibration_settings(table, ["true_params.coulomb1"], base)
    assert info.value.path == "calibrate.bounds.true_params.Mp"
    assert "replaces the file's fit list" in info.value.message
    assert "--fit true_params.EI1,true_params.EI2,true_params.Mp,true_params.coulomb1" in \
        info.value.message


def test_a_models_kinematics_and_joint_effects_are_part_of_its_name():
    """--compare's table (issue 60.4): the linear- and exact-kinematics reduced plants
    were both "reduced plant, 2+2 modes"; now their kinematics and joint effects tell
    them apart."""
    names = {}
    for kinematics in ("linear", "exact"):
        base = start_model(kinematics)
        plan = plan_calibration(base, calibration_settings(BOUNDS, FITTED, base),
                                [(data(duration=0.2), None)])
        names[kinematics] = model_description(plan)["plant"]
    assert names["linear"] != names["exact"]
    assert "linear kinematics" in names["linear"] and "exact kinematics" in names["exact"]
    assert "joint 1: Coulomb+viscous friction" in names["linear"]


# --- coloured noise -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def torque():
    t = np.arange(2000) * 1e-3
    return np.vstack([np.sin(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 3 * t),
                      0.5 * np.cos(2 * np.pi * 1.1 * t)])


def ar1(rng, shape, rho=0.9):
    w = rng.standard_normal(shape)
    for k in range(1, shape[-1]):
        w[..., k] = rho * w[..., k - 1] + math.sqrt(1 - rho ** 2) * w[..., k]
    return w


def test_coloured_noise_at_the_stated_level_is_noise_not_model_error(torque):
    """AR(1) noise of ρ = 0.9 at the stated RMS on four signals, 40 draws: called
    coloured noise, the model adequate, in at least 38 (the tests' family false-alarm
    rate is 0.01: P(X ≥ 3) = 0.008 for X ~ B(40, 0.01)); its noise model found as order
    1, ρ within 0.05.  Known-bad: before, every one was "MODEL INADEQUATE" (the issue)."""
    rng = np.random.default_rng(5)
    adequate = 0
    for _ in range(40):
        v = adequacy([Block("e", f"s{i}", r, 1.0, 1.0, torque)
                      for i, r in enumerate(ar1(rng, (4, 2000)))])
        adequate += v["model_adequate"] is True and v["noise_coloured"]
    assert adequate >= 38, adequate
    assert v["verdict"].startswith("model adequate, noise coloured")
    model = v["signals"]["e"]["s0"]["noise_model"]
    assert model["order"] == 1 and abs(model["coefficients"][0] - 0.9) < 0.05


@pytest.mark.parametrize("error", ["level", "inputs"])
def test_correlated_residual_above_the_level_or_following_the_inputs_is_model_error(
        torque, error):
    """Known-bad of the above: the same AR(1) noise at 1.5× the stated RMS (a correlated
    residual beyond the noise), or plus a filtered, delayed copy of the torque of 1.4×
    its RMS (the innovations follow it; at 0.35× the noise's own low-frequency power
    hides it: measured 2.6 against the threshold 4.4): a model error, not coloured
    noise."""
    rng = np.random.default_rng(6)
    e = ar1(rng, (4, 2000))
    if error == "level":
        e[1] *= 1.5
    else:
        lagged = np.concatenate([np.zeros(5), torque[0, :-5]])
        e[1] += 2.0 * np.convolve(lagged, np.ones(30) / 30, mode="same")
    v = adequacy([Block("e", f"s{i}", r, 1.0, 1.0, torque) for i, r in enumerate(e)])
    assert v["model_adequate"] is False and v["signals"]["e"]["s1"]["diagnosis"] == "model"
    assert not v["signals"]["e"]["s1"][error]["passed"]


def test_the_sandwich_covariance_of_ar1_noise_is_its_low_frequency_gain():
    """A smooth column under AR(1) noise of ρ = 0.9: the sandwich variance is the white
    one times (1+ρ)/(1−ρ) = 19 (the noise's spectral density at low frequency; to 2 %,
    the column's own curvature and the filter's start), where the white formula gives 1."""
    rng = np.random.default_rng(7)
    e = ar1(rng, (1, 20000))[0]
    model = fit_noise(e)
    t = np.linspace(0, 1, e.size)
    J = np.column_stack([np.sin(2 * np.pi * t), t])
    rows = [np.arange(e.size)]
    white = parameter_uncertainty(J, e, ["p.a", "p.b"], np.ones(2), np.ones(2))
    coloured = parameter_uncertainty(J, e, ["p.a", "p.b"], np.ones(2), np.ones(2),
                                     meat=sandwich_meat(J, rows, [model]))
    for name in ("p.a", "p.b"):
        ratio = (coloured["parameters"][name]["std"] / white["parameters"][name]["std"]) ** 2
        assert ratio == pytest.approx(19 * model.variance / float(e @ e / e.size), rel=0.05)
    assert coloured["interval_kind"] == "95 % (the noise, coloured: its correlation counted)"


def test_a_fit_on_coloured_noise_says_so_and_its_intervals_cover(tmp_path):
    """The right model on AR(1) noise (ρ = 0.9) at the stated level: "model adequate,
    noise coloured", and its 95 % intervals — the sandwich, 3-5 times the white ones —
    hold every true value (20 seeds on the truth plant: bench_calibration_coverage.py
    --case ar1).  Known-bad: the white formula's intervals at this estimate are 3-5
    times narrower."""
    result = fit(tmp_path, start_model(), FITTED, [data(noise="ar1")], table=BOUNDS)
    assert result["model_adequate"] is True and result["adequacy"]["noise_coloured"]
    assert result["adequacy"]["verdict"].startswith("model adequate, noise coloured")
    assert all(covers(result, TRUE).values()), result["parameters"]
    assert "coloured" in result["interval_kind"]
    assert not result["screen"][0]["significant"], result["screen"][0]


# --- the physics an inadequate model lacks ---------------------------------------------
def exported_ranges(folder) -> dict:
    """The ranges uncertainty.toml hands flexarm verify ({} where it is not written)."""
    from validation.run.tomlfiles import load_toml
    path = folder / "uncertainty.toml"
    if not path.is_file():
        return {}
    return {n: tuple(v["uniform"]) for n, v in load_toml(path)["uncertainty"].items()}


def without(monkeypatch, name):
    """The search with candidate ``name`` removed (the known-bad of each search)."""
    every = extensions_room.candidates

    def fewer(plan, estimate):
        return [e for e in every(plan, estimate) if e.name != name]
    monkeypatch.setattr(extensions_room, "candidates", fewer)
    monkeypatch.setattr(workflow, "candidates", fewer)


def test_the_screen_ranks_the_missing_stribeck_effect_first(tmp_path):
    """The data have a Stribeck effect (breakaway 0.4 above the Coulomb level 0.25), the
    model none: inadequate, and the screen's most significant candidate is the joint-1
    Stribeck effect (the search itself, and its known-bad: the slow tests below).
    Known-good: on the right model the screen finds nothing (the coloured-noise fit)."""
    extra = {"breakaway1": 0.4, "stribeck_velocity1": 0.01}
    result = fit(tmp_path, start_model(), FITTED, [data(extra)], table=BOUNDS)
    assert result["model_adequate"] is False and "extensions" not in result
    top = result["screen"][0]
    assert top["name"] == "joint 1 Stribeck friction" and top["significant"], top
    assert top["score"] > 3 * result["screen"][1]["score"], result["screen"][:2]


@pytest.mark.slow  # each known-bad fits three other candidates: 1-2 min
@pytest.mark.parametrize("case, extra, kinematics, reference, named", [
    ("stribeck", {"breakaway1": 0.375, "stribeck_velocity1": 0.01}, "linear", REVERSALS,
     "joint 1 Stribeck friction"),
    ("kinematics", {}, "exact", None, "exact kinematics"),
])
def test_an_inadequate_model_is_told_what_it_lacks(tmp_path, monkeypatch, case, extra,
                                                   kinematics, reference, named):
    """The data have a Stribeck effect (breakaway 0.375, 1.5× the Coulomb 0.25: the top of
    the field's typical range, 1-1.5×, whose 1.1× and 1.4× the screen probes), or exact
    kinematics under large motion (the paper's reference from rest); the model has neither:
    inadequate, and the search names the extension that makes it adequate, its fit written
    to OUT/extended/; the inadequate model's own ranges are not exported, and every range
    the extended fit exports holds the truth (it exports none where a parameter is not
    identifiable: the breakaway and the Stribeck velocity, barely seen, fitted as 0.3738 and
    0.0102, and EI1, EI2, Mp then 2.2-2.5 standard errors off).  Known-bad: with that
    extension removed from the candidates, the verdict says none was found.

    Not 0.4 (1.6×, beyond the typical range): the search's fit starts at its best probe,
    1.4× the estimated Coulomb level (0.353), and stops at 0.343 (cost 4978 against 4022
    at the truth; measured), a minimum of its own piece of the cost: a reversal's stick
    moves by a whole 1 ms step there, and the cost jumps (others at the truth: 64323 at
    0.39, 5201 at 0.395).  From 0.38-0.5 the same fit reaches 0.399-0.406, adequate;
    at 0.375 the cost (others at the truth) has no jump from 0.27 to 0.3825."""
    experiment = data(extra, kinematics=kinematics, reference=reference)
    result = fit(tmp_path / "all", start_model(), FITTED, [experiment], table=BOUNDS,
                 search=True)
    assert result["model_adequate"] is False
    search = result["extensions"]
    assert search["adequate"] == named, search["verdict"]
    assert search["verdict"].startswith(f"with {named} the model is adequate")
    out = tmp_path / "all" / "out"
    assert not (out / "uncertainty.toml").exists()
    assert (out / "extended" / "calibrated.toml").is_file()
    exported = exported_ranges(out / "extended")
    truth = {**TRUE, **extra}
    assert all(lo <= truth[n.split(".")[1]] <= hi for n, (lo, hi) in exported.items()), exported
    without(monkeypatch, named)
    blind = fit(tmp_path / "blind", start_model(), FITTED, [experiment], table=BOUNDS,
                search=True)
    assert blind["extensions"]["adequate"] is None
    assert blind["extensions"]["verdict"].startswith(("none of the extensions tried",
                                                      "no physics extension"))
    assert not (tmp_path / "blind" / "out" / "extended").exists()


@pytest.mark.slow
def test_an_unmodelled_drive_with_backlash_is_named(tmp_path, monkeypatch):
    """The issue's outside check on the reduced plant: a drive on joint 1 (3000 N m/rad,
    rotor 0.05 kg m², damping 2) with backlash 2e-4 rad, absent from the model: the
    payload comes out +38 % (measured), inadequate; the search fits the drive, then the
    drive with backlash from it, and names the latter, recovering the drive within 1 %;
    every range it exports holds the truth (measured: none — the backlash, 2.04e-4, is
    not identifiable, and the stiffness's interval at its estimate misses 3000 by 5.7
    standard errors).  Known-bad: without the backlash candidate, none is adequate."""
    drive = {"gear_stiffness1": 3e3, "rotor_inertia1": 0.05, "gear_damping1": 2.0,
             "backlash1": 2e-4}
    experiment = data(drive)
    result = fit(tmp_path / "all", start_model(), FITTED, [experiment], table=BOUNDS,
                 search=True)
    assert result["model_adequate"] is False
    assert result["extensions"]["adequate"] == "joint 1 drive with backlash"
    found = next(f for f in result["extensions"]["fits"] if f["model_adequate"])
    truth = {**TRUE, **drive}
    for name in ("gear_stiffness1", "rotor_inertia1"):
        assert abs(found["parameters"][f"true_params.{name}"]["estimate"] / truth[name] - 1) \
            < 0.01, found["parameters"]
    exported = exported_ranges(tmp_path / "all" / "out" / "extended")
    assert all(lo <= truth[n.split(".")[1]] <= hi for n, (lo, hi) in exported.items()), exported
    without(monkeypatch, "joint 1 drive with backlash")
    blind = fit(tmp_path / "blind", start_model(), FITTED, [experiment], table=BOUNDS,
                search=True)
    assert blind["extensions"]["adequate"] is None
