"""The paper's PBC fed by its SMO on every example arm, both plants, as
``campaigns/arms.toml`` runs it; the PBC holding the vertical arms against gravity, and
sagging by the static moment over its gain without the gravity term; the report's arms
side by side."""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from controllers import CONTROLLERS
from reduced_model import ArmModel, named_arm
from validation import expand, load_campaign, run_scenario, scenario_from_mapping
from validation.run.metrics import all_metrics
from validation.run.scenario import scenario_to_mapping
from validation.report.arms import arms_answers, arms_table

CAMPAIGN = Path(__file__).parents[1] / "campaigns" / "arms.toml"
VERTICAL = ("vertical-single-link", "vertical-two-link")


def planned():
    return expand(load_campaign(CAMPAIGN))


def test_the_campaign_runs_every_law_on_every_arm_and_plant():
    runs = planned()
    cells = {(r.scenario.arm, r.scenario.plant.kind, r.scenario.name.split("/")[-1])
             for r in runs}
    arms = {r.scenario.arm for r in runs}
    assert arms == {"single-link", "rigid-flexible", "default", "three-link", *VERTICAL}
    assert len(runs) == len(cells) == len(arms) * 2 * 4


def _smo_runs():
    return {(r.scenario.arm, r.scenario.plant.kind): r.scenario for r in planned()
            if r.scenario.name.endswith("pbc+smo-paper")}


#: RMS of θ − θ_d over 3–5 s (after the 2 s move), each joint, the campaign's sensor noise:
#: measured ≤ 0.70 mrad on every arm and plant (the paper's arm; 0.12–0.29 on the others).
FINAL_ERROR = 1e-3


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
@pytest.mark.parametrize("arm", ["single-link", "rigid-flexible", "default", "three-link",
                                 *VERTICAL])
def test_pbc_fed_by_the_smo_tracks_and_the_vibration_decays(arm, plant):
    """Each joint within `FINAL_ERROR` RMS after 3 s; each flexible link's vibration RMS
    over 2–4 s below 0.7 of the first 2 s' (measured: ≤ 0.025 on the example arms, 0.49
    and 0.21 on the paper's arm, whose 0.5 Hz first mode rings longest)."""
    scenario = _smo_runs()[(arm, plant)]
    result = run_scenario(scenario)
    assert result.status == "ok", result.message
    m = all_metrics(result, scenario.transient)
    N = ArmModel(named_arm(arm)).n_joints
    rms = [m[f"track_rms_{i}"] for i in range(1, N + 1)]
    assert max(rms) < FINAL_ERROR, rms
    for link, params in enumerate(named_arm(arm).links, start=1):
        if params.modes:
            assert m[f"vib_win_{link}_02"] < 0.7 * m[f"vib_win_{link}_00"], link


def test_the_tracking_bound_refuses_an_observer_band_wider_than_the_deflections():
    """Known bad: the SMO with the paper's arm's L_P,q = 0.5 m/s on the three-link arm,
    whose modes are 3.6× stiffer (the rule gives 0.04): the ±0.5 mm band in q̂ biases the
    light third joint's rate estimate and its angle settles 2.5 mrad off."""
    scenario = _smo_runs()[("three-link", "reduced")]
    spec = scenario_to_mapping(scenario)
    spec["observer"]["options"] = {"l_position": [1.0, 0.5]}
    result = run_scenario(scenario_from_mapping(spec))
    m = all_metrics(result, scenario.transient)
    assert m["track_rms_3"] > 2 * FINAL_ERROR


def hold(arm, plant, gravity_compensation=True, duration=5.0):
    N = named_arm(arm).n_links
    result = run_scenario(scenario_from_mapping({
        "arm": arm, "duration": duration, "plant": {"kind": plant},
        "controller": {"kind": "pbc", "options": {"gravity_compensation": gravity_compensation}},
        "observer": {"kind": "none"}, "feedback": "true",
        "reference": {"kind": "quintic", "start": [0.0] * N, "goal": [0.0] * N,
                      "move_time": 2.0}}))
    assert result.status == "ok", result.message
    return result, N


#: |θ| at the end of a 5 s hold, arm straight out: measured 4.4e-17 and 8.5e-8 rad on the
#: reduced plant (single, two links), 1.3e-5 and 2.3e-6 on the truth plant.
HOLD_ERROR = 1e-4


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
@pytest.mark.parametrize("arm", VERTICAL)
def test_the_pbc_holds_a_vertical_arm_horizontal(arm, plant):
    result, N = hold(arm, plant)
    error = [abs(result[f"theta{i}"][-1]) for i in range(1, N + 1)]
    assert max(error) < HOLD_ERROR, error


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
@pytest.mark.parametrize("arm", VERTICAL)
def test_without_the_gravity_term_the_pbc_sags_by_the_static_moment_over_its_gain(arm, plant):
    """Known bad of the hold: at rest the PBC's torque is K_v Λ (θ_d − θ), so without its
    gravity term the joints settle where K_v Λ e = g_θ(settled arm): measured to 1e-12 on
    the reduced plant and 4e-4 on the truth plant (its settled state read through the
    reduced model's g); 1 % is the issue's bound."""
    result, N = hold(arm, plant, gravity_compensation=False, duration=8.0)
    model = ArmModel(named_arm(arm))
    law = CONTROLLERS["pbc"](model, Ts=1e-3)
    settled = np.array([result[name][-1] for name in model.coordinate_names])
    sag = np.array([result[f"theta{i}_ref"][-1] - result[f"theta{i}"][-1]
                    for i in range(1, N + 1)])
    want = model.gravity_force(settled)[:N] / (law.kv[:N] * law.lam[:N])
    np.testing.assert_allclose(sag, want, rtol=0.01)
    assert np.all(np.abs(sag) > 100 * HOLD_ERROR)


def _run(arm, name, role, status="ok", **metrics):
    return SimpleNamespace(arm=arm, name=f"arms/{name}", role=role, status=status,
                           end_time=1.5, metrics=metrics)


def test_the_report_puts_the_arms_side_by_side():
    """Known good: two arms give a sentence per arm and plant and a row per arm and system,
    each value the worst joint's; a diverged run says so.  Known bad: one arm, no section."""
    runs = [_run("three-link", "pbc", "reduced", track_rms_1=1e-4, track_rms_3=3e-4),
            _run("three-link", "pbc", "truth", "diverged"),
            _run("single-link", "pbc", "reduced", track_rms_1=2e-4),
            _run("single-link", "pbc", "truth", track_rms_1=5e-4)]
    answers = arms_answers(runs)
    assert answers == [
        "three-link arm, truth plant: tracking error RMS after the transient (worst joint) "
        "pbc diverged at 1.5 s.",
        "three-link arm, reduced model: tracking error RMS after the transient (worst "
        "joint) pbc 0.3 mrad.",
        "single-link arm, truth plant: tracking error RMS after the transient (worst joint) "
        "pbc 0.5 mrad.",
        "single-link arm, reduced model: tracking error RMS after the transient (worst "
        "joint) pbc 0.2 mrad."]
    rows = arms_table(runs)["rows"]
    assert [row[:3] for row in rows] == [["three-link", "pbc", "0.3 / DIVERGED"],
                                         ["single-link", "pbc", "0.2 / 0.5"]]
    assert arms_answers(runs[:2]) == [] and arms_table(runs[:2]) is None
