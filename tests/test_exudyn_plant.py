"""ExudynPlant behind the Plant interface: projection, initial states, stepping, sensors,
errors, and the joint-2 stability that motivates the default stator inertia."""
import os

import exudyn as exu
import numpy as np
import pytest

from controllers import JointPD, PaperReference
from plant_exudyn import ExudynPlant, LinkField, Mesh
from reduced_model import ArmModel, ArmParameters, PlantFailure, ReducedPlant, SensorConfig
from reduced_model.contract import true_state_from_vector

MESHES = [Mesh("ancf", (4, 4)), Mesh("geometrically_exact", (8, 6))]


@pytest.fixture(scope="module", params=MESHES, ids=lambda m: m.element)
def plant(request):
    return ExudynPlant(mesh=request.param)


def test_behaves_as_a_plant(plant):
    """What the closed loop (validation.run.loop) relies on, checked on numbers rather than on
    method names: reset returns y(0) of the given state, truth_vector() is truth()
    flattened, step holds the torque for Ts and returns y(t + Ts), and the torque moves
    the arm as it moves the reduced plant."""
    assert plant.role == "truth" and plant.state_size == 12
    x0 = np.zeros(12)  # undeformed and moving, as the loop starts a run
    x0[:2], x0[6:8] = (0.3, -0.5), (0.2, 0.1)
    y = plant.reset(x0)
    assert y.time == 0.0 and y.names == ("theta1", "theta2", "q11", "q12", "q21", "q22")
    # An undeformed arm is placed exactly (measured 6e-18): round-off only.
    np.testing.assert_allclose(y.values, x0[:6], atol=1e-14)
    vector, truth = plant.truth_vector(), plant.truth()
    back = true_state_from_vector(truth.time, vector, 2)
    np.testing.assert_array_equal(vector[:12], truth.x)
    np.testing.assert_array_equal(back.tip_positions, truth.tip_positions)
    np.testing.assert_array_equal(back.tip_deflections, truth.tip_deflections)
    np.testing.assert_array_equal(back.projection_residual, truth.projection_residual)

    def response(p, tau, steps=10):
        p.reset(x0)
        for _ in range(steps):
            y = p.step(tau)
        return y, p.truth()

    tau = np.array([0.5, -0.3])
    y, pushed = response(plant, tau)
    assert y.time == pytest.approx(0.01, abs=1e-15) and pushed.time == y.time == plant.time
    np.testing.assert_array_equal(y.values, pushed.x[:6])  # direct sensors read the truth
    free = response(plant, np.zeros(2))[1]
    red = ReducedPlant()
    effect = pushed.theta_dot - free.theta_dot
    effect_red = response(red, tau)[1].theta_dot - response(red, np.zeros(2))[1].theta_dot
    # The torque's own effect on the joint rates after 10 ms (θ̇2: −0.23 rad/s) agrees with
    # the reduced plant to 4.9 % (measured, both meshes): within 10 ms the FE arm's modes
    # above the reduced model's 2+2 still respond.  10 % also catches a wrong sign, a
    # missing stator reaction (−τ2 on link 1) or a torque applied twice.
    np.testing.assert_allclose(effect, effect_red, rtol=0.1)


@pytest.mark.parametrize("link", [0, 1])
def test_projection_recovers_modal_fields_exactly(plant, link):
    field: LinkField = plant.fields[link]
    q = np.array([3e-3, -1e-3])
    d = field.nodal_modes @ q  # the FE link carrying Σ φ_j q_j (nodal values and slopes)
    # Normal equations with the same quadrature's Gram matrix: exact to round-off.
    np.testing.assert_allclose(field.project(d), q, rtol=1e-12, atol=1e-15)
    assert field.residual(d, q) < 1e-12


def test_undeformed_arm_has_no_modal_coordinates(plant):
    x0 = np.zeros(12)
    x0[:2] = [0.7, -1.9]
    plant.reset(x0)
    truth = plant.truth()
    np.testing.assert_allclose(truth.theta, [0.7, -1.9], atol=1e-14)
    np.testing.assert_allclose(truth.q, 0.0, atol=1e-14)
    np.testing.assert_allclose(truth.projection_residual, 0.0, atol=1e-14)
    L1, L2 = plant.params.L1, plant.params.L2
    tip = L1 * np.exp(0.7j) + L2 * np.exp(0.7j - 1.9j)
    np.testing.assert_allclose(truth.tip_positions[1], [tip.real, tip.imag], atol=1e-14)


def test_reset_places_a_modal_state(plant):
    x0 = np.array([0.4, 1.1, 2e-3, -4e-4, 1e-3, 2e-4, 0.5, -0.3, 0.02, 0.01, -0.03, 0.005])
    plant.reset(x0)
    truth = plant.truth()
    np.testing.assert_allclose(truth.theta, x0[:2], atol=1e-12)
    # Nodes lie on the inextensible curve y = ∫ sin(atan w'): third order in the slope
    # (~1e-8 here) plus the 4001-point trapezoid (1e-10), so q and θ̇ agree to ~1e-7.
    np.testing.assert_allclose(truth.q, x0[2:6], rtol=1e-4, atol=1e-8)
    np.testing.assert_allclose(truth.theta_dot, x0[6:8], atol=1e-7)
    np.testing.assert_allclose(truth.q_dot, x0[8:], rtol=1e-4, atol=1e-7)
    assert truth.time == 0.0


def elastic_energy(plant) -> float:
    """Elastic energy of the FE links as Exudyn computes it."""
    mbs, total = plant.system.mbs, 0.0
    for obj in range(mbs.systemData.NumberOfObjects()):
        if mbs.GetObject(obj)["objectType"] in ("ANCFCable2D", "BeamGeometricallyExact2D"):
            total += mbs.GetObjectOutputBody(obj, exu.OutputVariableType.PotentialEnergy,
                                             localPosition=[0, 0, 0])
    return total


def test_reset_places_the_modal_strain_energy(plant, request):
    """The projection of q (test above) cannot see strain that the modes do not carry: the
    placed FE arm must also store the modal state's elastic energy ½ qᵀ K q."""
    if plant.mesh.element == "geometrically_exact":
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            "library bug: reset() of a geometrically exact mesh stores 10.9x the modal "
            "strain energy (8+6 elements; 1.1 % at 32+32), and stepping from a deflected "
            "link 2 then fails in Exudyn's Newton iteration")))
    x0 = np.array([0.4, 1.1, 2e-3, -4e-4, 1e-3, 2e-4, 0.5, -0.3, 0.02, 0.01, -0.03, 0.005])
    plant.reset(x0)
    expected = ArmModel(plant.params).potential_energy(x0[:6])
    # ANCF cubic elements carry the smooth mode shapes' curvature closely: measured 5e-4
    # relative at 4 elements per link; 1 % leaves room for a finer or coarser mesh.
    assert elastic_energy(plant) == pytest.approx(expected, rel=1e-2)


def test_period_stepping_matches_one_continuous_run():
    a, b = ExudynPlant(), ExudynPlant(Ts=1.0)
    a.reset()
    b.reset()
    for _ in range(1000):
        a.step([0.3, -0.2])
    b.step([0.3, -0.2])
    # SolveSteps re-requests the Jacobian at each call, so the Newton iterates differ
    # within the 1e-6 tolerance: measured 8e-8 rad after 3 s, 600× below the 1 ms
    # time-step error.
    np.testing.assert_allclose(a.truth().theta, b.truth().theta, atol=1e-6)
    assert a.time == b.time == 1.0


def test_agrees_with_reduced_plant_on_a_gentle_move():
    fe, red = ExudynPlant(), ReducedPlant()
    fe.reset()
    red.reset()
    q11 = np.empty((2, 2000))
    for k in range(2000):
        fe.step([0.3, -0.2])
        red.step([0.3, -0.2])
        q11[:, k] = fe.truth().q[0], red.truth().q[0]
    # 2 s of constant torque: the 2+2-mode model stays within 1e-3 rad (measured 6e-4).
    np.testing.assert_allclose(fe.truth().theta, red.truth().theta, atol=1e-3)
    # The torque step rings the lightly damped 13.6 Hz stator mode, whose frequency the
    # reduced model has 0.4 % high: 0.7 rad of phase after 2 s, so compare the
    # quasi-static deflection (last 0.5 s mean) to 2 %, not a snapshot.
    assert q11[0, -500:].mean() == pytest.approx(q11[1, -500:].mean(), rel=2e-2)


def pd_tracking(plant, kd2, seconds=3.0):
    """Joint PD at 1 kHz on the paper's reference from rest (true state fed back);
    returns the final joint error [rad], or inf if |q| left 0.5 or the solver failed."""
    plant.reset()
    # The gains this test was measured with: K_p = (40, 20), no feedforward.
    # (The model only feeds the feedforward, which is off.)
    pd = JointPD(ArmModel(), Ts=1e-3, kp=(40.0, 20.0), kd=(8.0, kd2), feedforward=False)
    ref = PaperReference()
    try:
        for k in range(int(round(seconds / 1e-3))):
            truth = plant.truth()
            plant.step(pd(k * 1e-3, truth.x, ref))
            if not np.abs(plant.truth().q).max() < 0.5:
                return np.inf
    except PlantFailure:
        return np.inf
    return np.abs(ref(seconds - 1e-3)[0] - truth.theta).max()


@pytest.mark.parametrize("make", [ExudynPlant, ReducedPlant], ids=["exudyn", "reduced"])
def test_default_stator_inertia_keeps_joint2_pd_stable(make):
    # Kd2 = 4 N m s/rad is a critically damped ~4 rad/s loop on joint 2.  Without stator
    # inertia the sampled D-term destabilises the link-1 tip on both plants (measured:
    # divergence within 10 ms); with the default 0.01 kg m² it tracks: the reference
    # starts at 0.6 and 1.3 rad/s, the PD catches up in ~2.5 s; measured 0.035 rad at 3 s.
    assert pd_tracking(make(ArmParameters()), kd2=4.0) < 0.06
    assert pd_tracking(make(ArmParameters(stator_inertia=0.0)), kd2=4.0) == np.inf


def test_sensors_encoders_gauges_tip():
    cfg = SensorConfig(encoder_resolution=2 * np.pi / 4096, strain_gauges=((0.05, 0.2, 0.35),
                       (0.05, 0.25)), rates=True, tip_position=True)
    plant = ExudynPlant(sensors=cfg)
    x0 = np.array([0.4, 1.1, 2e-3, -4e-4, 1e-3, 2e-4, 0, 0, 0, 0, 0, 0])
    y = plant.reset(x0)
    assert y.names == ("theta1", "theta2", "q11", "q12", "q21", "q22", "theta1_dot",
                       "theta2_dot", "q11_dot", "q12_dot", "q21_dot", "q22_dot", "tip_x", "tip_y")
    counts = y.values[:2] / cfg.encoder_resolution
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert abs(y["theta1"] - 0.4) <= cfg.encoder_resolution / 2
    truth = plant.truth()
    # Curvature of the FE interpolation at the gauges vs the modal fit of the whole
    # field: ANCF curvature is piecewise linear, so the fits differ by a few percent.
    np.testing.assert_allclose(y.values[2:6], truth.q, rtol=0.05, atol=2e-5)
    np.testing.assert_allclose(y.values[-2:], truth.tip_positions[1], atol=1e-15)


def test_reduced_plant_gauges_are_exact_and_direct_path_agrees():
    x0 = np.array([0.4, 1.1, 2e-3, -4e-4, 1e-3, 2e-4, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    gauges = SensorConfig(strain_gauges=((0.1, 0.3), (0.1, 0.4)), rates=True)
    direct = ReducedPlant(sensors=SensorConfig(rates=True)).reset(x0)
    fitted = ReducedPlant(sensors=gauges).reset(x0)
    assert direct.names == fitted.names
    # The reduced plant's deflection is modal: two gauges per link recover q exactly.
    np.testing.assert_allclose(fitted.values, direct.values, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(direct.values, x0)


@pytest.mark.parametrize("kwargs, match", [
    (dict(mesh=Mesh(elements_per_link=(4, 4)), step=0.0), "step must be a positive"),
    (dict(spectral_radius=1.5), "spectral_radius"),
    (dict(sensors=SensorConfig(strain_gauges=((0.1,), (0.1, 0.2)))), "link 1 has 1 gauge"),
    (dict(sensors=SensorConfig(strain_gauges=((0.1, 0.9), (0.1, 0.2)))), r"positions must lie"),
    (dict(sensors=SensorConfig(strain_gauges=((0.2, 0.2), (0.1, 0.3)))), "cannot distinguish"),
])
def test_bad_construction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ExudynPlant(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(element="beam"), "mesh.element"), (dict(elements_per_link=(0, 4)), "elements_per_link"),
    (dict(elements_per_link=(4.0, 4)), "elements_per_link"), (dict(axial_stiffness=-1.0), "axial"),
])
def test_bad_mesh(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Mesh(**kwargs)


def test_bad_steps():
    with pytest.raises(ValueError, match="not a whole multiple"):
        ExudynPlant(Ts=1.25e-3)  # 2.5 steps of 0.5 ms
    plant = ExudynPlant()
    plant.reset()
    with pytest.raises(ValueError, match=r"takes 2 torques, got shape \(6,\)"):
        plant.step(np.zeros(6))
    with pytest.raises(TypeError, match="takes no Ts"):  # Ts is the plant's, given once
        plant.step([0.0, 0.0], 1e-3)
    with pytest.raises(ValueError, match="state0 must be 12"):
        plant.reset(np.zeros(4))


def test_solver_failure_is_reported_and_nothing_is_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    plant = ExudynPlant()
    # An absolute Newton tolerance below ANCF round-off can never be met: a system at rest never converges.
    plant.settings.timeIntegration.newton.absoluteTolerance = 1e-16
    plant.settings.timeIntegration.newton.relativeTolerance = 1e-16
    plant.reset()
    with pytest.raises(PlantFailure, match="Exudyn solver failed at t = .*step size"):
        for _ in range(200):
            plant.step([5.0, -5.0])
    assert os.listdir(tmp_path) == []


def test_modal_basis_of_another_model_must_match_lengths():
    other = ArmModel(ArmParameters(L1=0.6))
    with pytest.raises(ValueError, match="mode shapes are for L = 0.6"):
        ExudynPlant(model=other)


@pytest.mark.parametrize("n, labels", [
    (4, ["ANCF 8 el/link, step/2", "ANCF 16 el/link, step/4", "GE 32 el/link, step/2"]),
    # Known-bad (before): 16 el/link raised "mesh.elements_per_link must be an integer
    # 1..64 ..., got [128, 128]" building the label of the GE check it then left out:
    # `flexarm stability campaigns/paper.toml` exited 2 after 338 s, at its level-2 map.
    (16, ["ANCF 32 el/link, step/2", "ANCF 64 el/link, step/4"]),
    (64, []),
])
def test_refinements_beyond_64_elements_are_left_out(n, labels):
    from validation.run.plants import plant_settings
    plant = plant_settings({"kind": "exudyn", "mesh": {"elements_per_link": [n, n]}})
    assert [r.label for r in plant.refinements()] == labels
