"""Friction and drive parameters identified (``flexarm calibrate --fit
true_params.coulomb1,viscous1,…``): sensible starts and bounds, a Jacobian that does
not read a stick–slip jump as a slope, and the fits the issue names.

Known-good: a plant with friction fitted to its own kind of data (velocity reversals,
the campaigns' sensor noise) is adequate, within 5 %, and its 95 % intervals cover.
Known-bad: the paper's reduced model fitted to FE data with friction is flagged
inadequate, and no interval it reports misses the hidden value.  Data are made by the
toolkit's closed loop at stated values (`test_calibration.experiment`).
"""
import math

import numpy as np
import pytest

from test_calibration import NOISE, fit, model
from test_calibration_adequacy import covers
from validation import cli, run_scenario, scenario_from_mapping
from validation.run.experiments import from_run
from validation.run.config import ConfigError
from validation.verdicts.calibration.differences import AGREEMENT, jacobian, one_sided
from validation.verdicts.calibration.polish import polish
from validation.verdicts.calibration import calibration_settings

#: The issue's lab arm with joint-1 friction (hidden: the fits start away from it).
HIDDEN = {"EI1": 8.6, "EI2": 11.3, "Mp": 0.37, "coulomb1": 0.3, "viscous1": 0.2}
FITTED = [f"true_params.{n}" for n in HIDDEN]
START = {"EI1": 9.5, "EI2": 10.0, "Mp": 0.3, "coulomb1": 0.25, "viscous1": 0.25}
#: An experiment designed for friction: joint velocities through zero at 0.5, 1.5 s
#: (joint 1) and 0.38, 1.15, 1.92 s (joint 2); 0.2 rad keeps the links' bending small.
REVERSALS = {"kind": "paper", "amplitude": [0.2, 0.2], "omega": [math.pi, 1.3 * math.pi]}
GE16 = {"element": "geometrically_exact", "elements_per_link": [16, 16]}


def lab_data(plant="reduced", *, seed=1, duration=2.0, mesh=None, ekf=False, params=HIDDEN):
    """Tracking with velocity reversals at the hidden values, its signals rounded to
    float32 as the store keeps them (the EKF-observed loop with a torque pulse where
    ``ekf``: the issue's lab)."""
    extra = {}
    if ekf:
        extra.update(observer={"kind": "ekf"}, disturbances=[{
            "kind": "pulse", "target": "tau1", "amplitude": 2.0, "start": 1.0,
            "duration": 0.1}])
    result = run_scenario(scenario_from_mapping({
        "duration": duration, "seed": seed, "sensors": NOISE, "true_params": params,
        "nominal_params": params, "reference": REVERSALS,
        "plant": {"kind": plant, **({"mesh": mesh} if mesh else {})}, **extra}))
    result.signals = result.signals.astype(np.float32)
    return from_run(result, "e1", "<e1>")


def start_model(plant="reduced", mesh=None, fitted=tuple(HIDDEN), **extra):
    """The fit's start: the ``fitted`` fields 10-25 % off (the others at the hidden
    values), its sensors' modal basis the data's."""
    start = {**HIDDEN, **{name: START[name] for name in fitted}}
    return scenario_from_mapping({
        "plant": {"kind": plant, **({"mesh": mesh} if mesh else {})}, "sensors": NOISE,
        "true_params": start, "nominal_params": HIDDEN, "reference": REVERSALS, **extra})


def within(result, fraction):
    return {n: abs(result["parameters"][f"true_params.{n}"]["estimate"] - v) / v <= fraction
            for n, v in HIDDEN.items()}


# --- starts and bounds -----------------------------------------------------------------------
def test_a_joint_field_at_zero_needs_a_start_and_bounds(tmp_path, capsys):
    """Known-bad: coulomb1 is 0 in the default arm; fitted with neither start nor bounds,
    the command refuses in one line naming the key, the typical range and an example,
    and writes nothing.  Known-good: the same with the example's start and bounds plans."""
    (tmp_path / "m.toml").write_text("[calibrate]\nfit = [\"true_params.coulomb1\"]\n")
    (tmp_path / "e.csv").write_text("t,tau1,tau2,theta1,theta2\n0,0.1,0,0,0\n0.001,0.1,0,1e-6,0\n")
    status = cli.main(["calibrate", str(tmp_path / "e.csv"), "--config",
                       str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert err.startswith("flexarm: error: --fit true_params.coulomb1: is 0 in the scenario")
    assert "0.1-1 N m" in err and '"true_params.coulomb1" = [0, 2]' in err
    assert not (tmp_path / "out").exists()
    settings = calibration_settings({"start": {"true_params": {"coulomb1": 0.3}},
                                     "bounds": {"true_params": {"coulomb1": [0.0, 2.0]}}},
                                    ["true_params.coulomb1"], model())
    assert (settings.parameters[0].start, settings.parameters[0].upper) == (0.3, 2.0)


@pytest.mark.parametrize("fitted, table, key, words", [
    (["coulomb1"], {"coulomb1": [0.0, 1.0]}, "calibrate.bounds.true_params.coulomb1",
     "above breakaway1 = 0.4 (fixed)"),
    (["gear_stiffness1"], {}, "calibrate.bounds.true_params.gear_stiffness1",
     "lower bound must be > 0 (0 is a rigid joint"),
    (["coulomb1", "breakaway1"], {}, "calibrate.bounds.true_params.breakaway1",
     "overlaps the bounds of true_params.coulomb1"),
    (["stribeck_velocity1"], {}, "calibrate.bounds.true_params.stribeck_velocity1",
     "lower bound must be > 0"),
])
def test_bounds_that_would_leave_the_arms_are_refused_naming_the_key(fitted, table, key,
                                                                      words):
    """The lab arm (breakaway 0.4 above Coulomb 0.3, drives): a bound that lets the fit
    try a point that is not an arm (a Coulomb level above the breakaway, a drive of zero
    stiffness, a breakaway below the Coulomb level) is refused before anything runs."""
    base = scenario_from_mapping({"arm": "lab"})
    bounds = {"true_params": table}
    with pytest.raises(ConfigError) as info:
        calibration_settings({"bounds": bounds}, [f"true_params.{n}" for n in fitted], base)
    assert info.value.path == key and words in info.value.message, str(info.value)


def test_bounds_a_tied_field_implies_are_its_defaults():
    """Known-good of the cases above: coulomb1 fitted with the lab arm's breakaway fixed
    is bounded by it; breakaway1 fitted with coulomb1 fixed starts its range at it; both
    fitted with bounds that do not overlap, and a drive with a positive lower bound,
    plan."""
    base = scenario_from_mapping({"arm": "lab"})
    (c,) = calibration_settings({}, ["true_params.coulomb1"], base).parameters
    (b,) = calibration_settings({}, ["true_params.breakaway1"], base).parameters
    assert (c.lower, c.upper) == (0.0, 0.4) and (b.lower, b.upper) == (0.3, math.inf)
    both = calibration_settings(
        {"bounds": {"true_params": {"coulomb1": [0.0, 0.35], "breakaway1": [0.35, 1.0],
                                    "gear_stiffness1": [1e3, 1e5]}}},
        ["true_params.coulomb1", "true_params.breakaway1", "true_params.gear_stiffness1"],
        base)
    assert [p.name for p in both.parameters][2] == "true_params.gear_stiffness1"


def test_a_start_that_is_not_an_arm_is_refused():
    """Joint 2's friction acts on the stator: an arm without stator inertia cannot start
    with it (the scenario's own reason, under calibrate.start)."""
    base = scenario_from_mapping({"true_params": {"stator_inertia": 0.0}})
    with pytest.raises(ConfigError, match="stator inertia") as info:
        calibration_settings({"start": {"true_params": {"coulomb2": 0.2}}},
                             ["true_params.coulomb2"], base)
    assert info.value.path == "calibrate.start"


# --- the Jacobian at a jump, and the estimate refined at the scale of its uncertainty --------
def staircase(jump_at, size, noise=0.0):
    """Residuals of two parameters, smooth (slopes 3 and −2 per unit, in 50 samples)
    plus, in the first, a jump of ``size`` where it crosses ``jump_at``: what a stick–
    slip transition moving across an integration step does; ``noise`` a fixed draw of
    that size added (the measurement's)."""
    rng = np.random.default_rng(0)
    shape = rng.standard_normal(50)
    offset = noise * rng.standard_normal(50)

    def residuals(points):
        return [3.0 * (u[0] - 1.0) * shape + 2.0 * (u[1] - 1.0) * np.roll(shape, 7)
                + (size * np.roll(shape, 3) if u[0] > jump_at else 0.0) + offset
                for u in points]
    return residuals, shape


def refine(residuals, u, h, column_noise=0.0):
    """`polish` from ``u`` with a first Jacobian of steps ``h`` (no float32 noise in the
    halves; ``column_noise`` the float32 noise of a column, which widens its steps)."""
    f = residuals([u])[0]
    lower, upper = np.zeros(2), np.full(2, np.inf)
    J, _ = jacobian(residuals, u, f, h, lower, upper, 0.0)
    return polish(residuals, u, f, J, lower, upper, largest=h, column_noise=column_noise,
                  halves_noise=0.0, floor=np.zeros(2), collinear=1e-3)


def test_the_refined_jacobian_steps_over_the_uncertainty_not_the_fits_step():
    """Known-good: residual noise 1e-5 (standard errors ~1e-6 of each parameter): the
    refined Jacobian's steps are 2 standard errors, or 1 % of the fit's step where that
    is more (1e-5), far below the jump 4e-4 above the estimate, and its columns are the
    smooth slopes (to 1e-6), settled.  Known-bad: the fit's central difference of step
    1e-3 crosses the jump and is ~5x off."""
    residuals, shape = staircase(1.0 + 4e-4, 3e-2, noise=1e-5)
    u, h = np.ones(2), np.full(2, 1e-3)
    f = residuals([u])[0]
    naive, _ = jacobian(residuals, u, f, h, np.zeros(2), np.full(2, np.inf), 0.0)
    assert np.linalg.norm(naive[:, 0] - 3 * shape) > 3 * np.linalg.norm(3 * shape)
    u_out, _, J, report, _ = refine(residuals, u, h)
    assert np.all(np.array([s["step"] for s in report]) <= 1e-5 * (1 + 1e-9))
    np.testing.assert_allclose(J[:, 0], 3 * shape, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(J[:, 1], 2 * np.roll(shape, 7), rtol=1e-6, atol=1e-9)
    assert all(s["settled"] for s in report)


def test_a_column_the_rounding_widened_across_a_jump_is_differenced_again_narrower():
    """The float32 rounding's floor widens the refined steps to the fit's, 1e-3 (a column
    noise of 1: more than 1e-3 of any column at a narrower step), across a jump 4e-4
    above the estimate (what coulomb1 on the truth plant did: polish.py's docstring).
    Known-good: the column is differenced again at half its step until it settles, at
    2.5e-4, and is the smooth slope (to 1e-6).  Known-bad: at the widened step it has not
    settled and is ~5x off (the first test above).  A jump at the estimate itself never
    settles: the halving stops at the narrowest step asked, and names the column."""
    residuals, shape = staircase(1.0 + 4e-4, 3e-2, noise=1e-5)
    u, r, J, report, _ = refine(residuals, np.ones(2), np.full(2, 1e-3), column_noise=1.0)
    assert report[0]["step"] == 2.5e-4 and report[0]["settled"], report
    np.testing.assert_allclose(J[:, 0], 3 * shape, rtol=1e-6, atol=1e-9)
    at, _ = staircase(1.0, 3e-2)
    u = np.ones(2)
    _, report = jacobian(at, u, at([u])[0], np.full(2, 1e-3), np.zeros(2),
                         np.full(2, np.inf), 0.0, narrowest=np.full(2, 1e-4))
    assert report[0]["step"] == 1.25e-4 and not report[0]["settled"], report
    assert report[1]["step"] == 1e-3 and report[1]["settled"]


def test_an_estimate_the_fit_left_away_from_the_minimum_is_refined_to_it():
    """The fit stopped 3.5 standard errors from the least-squares minimum along the
    first parameter (what the truth plant with friction did, polish.py's docstring): the
    refinement takes it there (within 0.1 standard error: its stopping rule) in one
    step, and stops.  Known-bad: the estimate it was given is 3.5 standard errors off."""
    residuals, shape = staircase(math.inf, 0.0, noise=0.02)
    A = np.column_stack([3 * shape, 2 * np.roll(shape, 7)])
    offset = residuals([np.ones(2)])[0]
    best = np.ones(2) - np.linalg.lstsq(A, offset, rcond=None)[0]
    std = np.sqrt(np.diag(np.linalg.inv(A.T @ A)) * (offset @ offset) / 48)
    start = best + np.array([3.5 * std[0], 0.0])
    u, r, J, report, steps = refine(residuals, start, np.full(2, 1e-3))
    assert steps == 1 and np.all(np.abs(u - best) < 0.1 * std), (u - best) / std


def test_a_column_that_does_not_settle_is_named():
    """A jump at the estimate itself: every forward half crosses it, the backward ones
    do not: the column is reported not settled, the smooth one settled."""
    residuals, _ = staircase(1.0, 3e-2)
    u = np.ones(2)
    J, report = jacobian(residuals, u, residuals([u])[0], np.full(2, 1e-3),
                         np.zeros(2), np.full(2, np.inf), noise=0.0)
    assert not report[0]["settled"] and report[0]["halves"] > AGREEMENT
    assert report[1]["settled"]


def test_a_parameter_on_its_bound_is_differenced_into_the_bounds():
    """At a bound the halves are the first and second steps into the bounds (one-sided,
    second order): exact for a quadratic residual."""
    assert list(one_sided(np.array([0.0, 1.0]), np.full(2, 1e-3), np.zeros(2),
                          np.full(2, 5.0))) == [1.0, 0.0]

    def residuals(points):
        return [np.array([u[0] ** 2 + 2 * u[0], u[1]]) for u in points]
    u = np.array([0.0, 1.0])
    J, report = jacobian(residuals, u, residuals([u])[0], np.full(2, 1e-3),
                         np.zeros(2), np.full(2, 5.0), noise=0.0)
    np.testing.assert_allclose(J, [[2.0, 0.0], [0.0, 1.0]], atol=1e-9)
    assert report[0]["formula"] == "one-sided" and report[1]["formula"] == "central"


# --- fits --------------------------------------------------------------------------------------
def test_the_reduced_plant_with_friction_fitted_to_its_own_data(tmp_path):
    """Known-good (the inverse crime with friction): 2 s of the reduced plant's tracking
    with velocity reversals, EI1, EI2, Mp, coulomb1, viscous1 from 10-25 % off: adequate,
    every estimate within 5 % (measured: within 4e-5), every 95 % interval covers, every
    parameter identifiable, every Jacobian column settled."""
    result = fit(tmp_path, start_model(), FITTED, [lab_data()])
    assert result["model_adequate"] is True, result["adequacy"]["verdict"]
    assert all(within(result, 0.05).values()), result["parameters"]
    assert all(covers(result, HIDDEN).values()), result["parameters"]
    assert all(p["identifiable"] and p["jacobian"]["settled"]
               for p in result["parameters"].values())


def test_the_truth_plant_with_friction_fitted_to_its_own_data(tmp_path):
    """Known-good on the truth plant (the cheap version of the slow test below): 1 s of
    its default mesh with friction and reversals, EI1, coulomb1 and viscous1 from 10-25 %
    off (the rest known): adequate, within 5 %, every 95 % interval covers (measured:
    standardised errors -1.59, +1.53, -1.55)."""
    fitted = ("EI1", "coulomb1", "viscous1")
    result = fit(tmp_path, start_model("exudyn", fitted=fitted),
                 [f"true_params.{n}" for n in fitted], [lab_data("exudyn", duration=1.0)])
    assert result["model_adequate"] is True, result["adequacy"]["verdict"]
    truth = {n: HIDDEN[n] for n in fitted}
    for name, value in truth.items():
        p = result["parameters"][f"true_params.{name}"]
        assert abs(p["estimate"] - value) <= 0.05 * value, (name, p)
    assert all(covers(result, truth).values()), result["parameters"]


def test_the_reduced_model_on_fe_data_with_friction_is_flagged_and_never_misses(tmp_path):
    """Known-bad: 1 s of the truth plant (its default mesh) with friction and reversals,
    fitted by the paper's reduced model: inadequate, and every interval it reports holds
    the hidden value (with κ = 3 EI1's missed by 1 % of its half-width: one of the two
    cases that moved `MODEL_ERROR_FACTOR` to 5)."""
    data = lab_data("exudyn", duration=1.0)
    result = fit(tmp_path, start_model(), FITTED, [data])
    assert result["model_adequate"] is False
    assert all(covers(result, HIDDEN).values()), result["parameters"]
    assert all(p["ci95"] is None for p in result["parameters"].values())


# --- the issue's outside check (slow) ------------------------------------------------------------
@pytest.mark.slow
def test_friction_coverage_of_the_inverse_crime_in_20_seeds(tmp_path):
    """20 noise seeds of the reduced plant's 2 s with reversals: each 95 % interval
    covers in 17-20 of 20 (P(X >= 17) = 0.98 for X ~ B(20, 0.95)), adequate on at least
    18 (the residual tests' family false-alarm rate 0.01), every estimate within 5 %."""
    covered = {n: 0 for n in HIDDEN}
    adequate = 0
    for seed in range(20):
        result = fit(tmp_path / str(seed), start_model(), FITTED, [lab_data(seed=seed)])
        adequate += result["model_adequate"] is True
        assert all(within(result, 0.05).values()), (seed, result["parameters"])
        for n, ok in covers(result, HIDDEN).items():
            covered[n] += ok
    assert all(17 <= c <= 20 for c in covered.values()), covered
    assert adequate >= 18, adequate


@pytest.mark.slow
def test_the_issues_lab_with_friction(tmp_path):
    """The issue's check, on two noise seeds: 2 s of the geometrically exact arm (16
    el/link) at the hidden values with joint-1 friction, EKF-observed tracking with
    reversals and a torque pulse.  The reduced model: inadequate, no interval that
    misses.  The truth plant's default mesh: flagged, or covering.  The truth plant on
    the data's own mesh fitting EI1, EI2, Mp, coulomb1, viscous1: adequate, within 5 %,
    every parameter with an interval; those are 95 % intervals, so one of the ten may
    miss (at least 8 of 10 cover: P(X <= 7) = 0.01 for X ~ B(10, 0.95)) and none by more
    than 3 standard errors (P = 0.027 for the ten; measured: 10 of 10, the worst seed 1's
    EI1 at -1.84 standard errors; seed 1's coulomb1 was 3.06 off while the refinement
    kept a column across a stick–slip jump, its standard error 4.5x too narrow: polish.py)."""
    ekf = {"observer": {"kind": "ekf"}}
    covered = 0
    for seed in (0, 1):
        data = lab_data("exudyn", seed=seed, mesh=GE16, ekf=True)
        reduced = fit(tmp_path / f"reduced{seed}", start_model(**ekf), FITTED, [data])
        assert reduced["model_adequate"] is False, seed
        assert all(covers(reduced, HIDDEN).values()), (seed, reduced["parameters"])
        default = fit(tmp_path / f"default{seed}", start_model("exudyn", **ekf), FITTED,
                      [data])
        assert default["model_adequate"] is False or all(covers(default, HIDDEN).values())
        own = fit(tmp_path / f"own{seed}", start_model("exudyn", GE16, **ekf), FITTED,
                  [data])
        assert own["model_adequate"] is True, (seed, own["adequacy"]["verdict"])
        assert all(within(own, 0.05).values()), (seed, own["parameters"])
        for name, value in HIDDEN.items():
            p = own["parameters"][f"true_params.{name}"]
            assert p["interval"] is not None, (seed, name, p["reason"])
            assert abs(p["estimate"] - value) <= 3 * p["std"], (seed, name, p)
        covered += sum(covers(own, HIDDEN).values())
    assert covered >= 8, covered


@pytest.mark.slow
def test_the_shipped_friction_example_recovers_its_arm(tmp_path, capsys):
    """The guide's command on examples/calibration/reversals.csv with friction.toml (the
    truth plant's default mesh, 2 s): adequate, within 5 % of the stated arm (EI1 9.2,
    EI2 10.6, Mp 0.23, coulomb1 0.25, viscous1 0.15), every 95 % interval covering
    (measured: within 2e-5, 46 s on two cores)."""
    from test_calibration import EXAMPLE
    out = tmp_path / "friction"
    assert cli.main(["calibrate", str(EXAMPLE / "reversals.csv"), "--config",
                     str(EXAMPLE / "friction.toml"), "--out", str(out), "--workers", "1",
                     "--no-progress"]) == 0
    assert '"model_adequate": true' in capsys.readouterr().out
    import json
    result = json.loads((out / "calibration.json").read_text())
    stated = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23, "coulomb1": 0.25, "viscous1": 0.15}
    for name, value in stated.items():
        p = result["parameters"][f"true_params.{name}"]
        assert abs(p["estimate"] - value) <= 0.05 * value, (name, p)
        assert p["interval"][0] <= value <= p["interval"][1], (name, p)
