"""Every built-in law on every example arm (single link, rigid–flexible, three links,
vertical single and two links): construction, the baselines' rigid inverse dynamics
against the model's public M, C and gravity, the gain rule, the LQR's schedule and its
operating points, and closed loops on the reduced plant (true state fed back)."""
import numpy as np
import pytest
import scipy.signal

from controllers import (CONTROLLERS, OBSERVERS, GainScheduledLQR, JointPD, QuinticMove,
                         RigidComputedTorque)
from controllers._gains import arm_gains
from reduced_model import ArmModel, named_arm
from validation import run_scenario, scenario_from_mapping

EXAMPLE_ARMS = ("single-link", "rigid-flexible", "three-link", "vertical-single-link",
                "vertical-two-link")
VERTICAL = ("vertical-single-link", "vertical-two-link")
GOAL = (0.5, -0.5, 0.5)  # a gentle move: half a radian per joint, alternating, in 2 s
TS = 1e-3
RNG = np.random.default_rng(57)


def model_of(arm: str) -> ArmModel:
    return ArmModel(named_arm(arm))


def random_state(model: ArmModel) -> np.ndarray:
    n, N = model.n, model.n_joints
    return np.concatenate([RNG.uniform(-3, 3, N), RNG.normal(0, 0.01, n - N),
                           RNG.normal(0, 1, N), RNG.normal(0, 0.1, n - N)])


def reference(N: int):
    return QuinticMove(start=(0.0,) * N, goal=GOAL[:N], duration=2.0)


@pytest.fixture(scope="module")
def lqr():
    """The default LQR of each example arm (and the paper's), designed once."""
    cache = {}

    def get(arm):
        if arm not in cache:
            cache[arm] = GainScheduledLQR(model_of(arm), Ts=TS)
        return cache[arm]
    return get


# --- construction ---------------------------------------------------------------------
@pytest.mark.parametrize("law", sorted(set(CONTROLLERS) - {"replay"}))
@pytest.mark.parametrize("arm", EXAMPLE_ARMS)
def test_every_controller_constructs_and_runs_on_every_arm(arm, law, lqr):
    model = model_of(arm)
    controller = lqr(arm) if law == "lqr" else CONTROLLERS[law](model, Ts=TS)
    tau = controller(0.7, random_state(model), reference(model.n_joints))
    rows = model.n if law == "pbc-idealised" else model.n_joints
    assert tau.shape == (rows,) and np.all(np.isfinite(tau))


@pytest.mark.parametrize("law", sorted(OBSERVERS))
@pytest.mark.parametrize("arm", EXAMPLE_ARMS)
def test_every_observer_constructs_and_runs_on_every_arm(arm, law):
    model = model_of(arm)
    observer = OBSERVERS[law](model, Ts=TS)
    x = random_state(model)
    assert observer.measured == model.state_names[:len(observer.measured)]
    observer.reset(x)
    for k in range(3):
        x_hat = observer.update(k * TS, x[:len(observer.measured)], np.ones(model.n_joints))
        assert x_hat.shape == (2 * model.n,) and np.all(np.isfinite(x_hat))


#: The RMS of θ̂ − θ after 3 s of the PBC fed by each observer, started 0.1 rad, 5 mm,
#: 0.3 rad/s, 0.05 m/s off, with the campaigns' sensor noise (1e-4 rad, 1e-5 m, 1e-3):
#: measured ≤ 6.4e-4 rad (smo-paper, smo-pos: the sign chatter in ±Ts·L_P = 1e-3 rad),
#: ≤ 6.0e-5 (smo-bl), ≤ 1.2e-5 (ekf), ≤ 3.7e-5 (ekf-pos) on every example arm.  The
#: sign band is the bound; an observer that did not converge keeps its 0.1 rad.
ESTIMATE_ERROR = 1e-3


@pytest.mark.parametrize("law", sorted(OBSERVERS))
@pytest.mark.parametrize("arm", EXAMPLE_ARMS)
def test_every_observer_closes_the_pbc_loop_on_every_arm(arm, law):
    model = model_of(arm)
    N = model.n_joints
    result = run_scenario(scenario_from_mapping({
        "arm": arm, "duration": 5.0, "controller": {"kind": "pbc"},
        "observer": {"kind": law, "initial_error": [0.1, 5e-3, 0.3, 0.05]},
        "feedback": "estimate",
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3},
        "reference": {"kind": "quintic", "start": [0.0] * N, "goal": list(GOAL[:N]),
                      "move_time": 2.0}}))
    assert result.status == "ok", result.message
    late = result.time >= 3.0
    for name in model.state_names[:N]:
        error = result["xhat_" + name][late] - result[name][late]
        assert np.sqrt(np.mean(error ** 2)) < ESTIMATE_ERROR, name


# --- the rigid arm's inverse dynamics --------------------------------------------------
def rigid_inverse_dynamics(model, theta, dtheta, ddtheta):
    """M_θθ θ̈ + C_θθ θ̇ + g_θ of the model at q = q̇ = 0, from its public M, C and
    gravity force."""
    N, n = model.n_joints, model.n
    Q, Qd = np.zeros(n), np.zeros(n)
    Q[:N], Qd[:N] = theta, dtheta
    return (model.mass_matrix(Q)[:N, :N] @ ddtheta + model.coriolis_matrix(Q, Qd)[:N, :N]
            @ dtheta + model.gravity_force(Q)[:N])


@pytest.mark.parametrize("arm", ("default",) + EXAMPLE_ARMS)
def test_baselines_invert_the_models_rigid_arm(arm):
    """PD and computed torque with zero gains are the rigid arm's inverse dynamics: of
    the reference for the PD, of the state and the commanded acceleration for computed
    torque.  Known bad: the PD without feedforward and gravity is 0 N m."""
    model = model_of(arm)
    N = model.n_joints
    pd = JointPD(model, Ts=TS, kp=0.0, kd=0.0)
    ct = RigidComputedTorque(model, Ts=TS, kp=0.0, kd=0.0)
    for _ in range(3):
        th, dth, ddth = RNG.uniform(-3, 3, N), RNG.uniform(-2, 2, N), RNG.uniform(-2, 2, N)
        want = rigid_inverse_dynamics(model, th, dth, ddth)
        x = np.zeros(2 * model.n)
        x[:N], x[model.n:model.n + N] = th, dth
        # The same M, C and g summed in another order: measured ≤ 5e-16 of the largest
        # torque on every arm; 1e-12 is round-off with room.
        atol = 1e-12 * np.abs(want).max()
        np.testing.assert_allclose(pd(0.0, np.zeros(2 * model.n), lambda t: (th, dth, ddth)),
                                   want, rtol=0, atol=atol)
        np.testing.assert_allclose(ct(0.0, x, lambda t: (th, dth, ddth)), want,
                                   rtol=0, atol=atol)
    bare = JointPD(model, Ts=TS, kp=0.0, kd=0.0, feedforward=False, gravity_compensation=False)
    assert np.all(bare(0.0, x, lambda t: (th, dth, ddth)) == 0.0)
    assert np.abs(want).max() > 0.01  # what the known-bad misses is not negligible


# --- the gain rule -----------------------------------------------------------------------
def test_the_gain_rule_gives_the_paper_defaults_on_the_paper_arm():
    pd, ct = JointPD(ArmModel(), Ts=TS), RigidComputedTorque(ArmModel(), Ts=TS)
    assert pd.kp.tolist() == [30.0, 15.0] and pd.kd.tolist() == [18.1, 8.2]
    assert ct.kp.tolist() == [11.1, 14.1] and ct.kd.tolist() == [6.7, 7.7]


@pytest.mark.parametrize("arm", EXAMPLE_ARMS)
def test_baseline_gains_place_the_pbc_joint_error_poles(arm):
    """PD: M_jj s² + K_d s + K_p = (M_jj s + K_v)(s + Λ); computed torque: s² + K_d s +
    K_p = (s + K_v/M_jj)(s + Λ), with the PBC's Λ, K_v of the arm's rule — up to the
    rounding (half of 0.1, or of the one significant figure kept below 1)."""
    model = model_of(arm)
    rule = arm_gains(model, TS)
    lam, kv, m = rule.lambda_joint, rule.kv_joint, rule.inertia
    pd, ct = JointPD(model, Ts=TS), RigidComputedTorque(model, Ts=TS)
    for got, want in ((pd.kp, kv * lam), (pd.kd, m * lam + kv), (ct.kp, lam * kv / m),
                      (ct.kd, lam + kv / m)):
        half = np.where(want >= 1.0, 0.05, 0.5 * 10.0 ** np.floor(np.log10(want)))
        assert np.all(np.abs(got - want) <= half * (1 + 1e-12)), (got, want)
        assert np.all(got > 0)


# --- the LQR's schedule ----------------------------------------------------------------------
@pytest.mark.parametrize("arm, scheduled, designs", [
    ("default", (1,), 24), ("single-link", (), 1), ("rigid-flexible", (1,), 24),
    ("three-link", (1, 2), 144), ("vertical-single-link", (0,), 24),
    ("vertical-two-link", (0, 1), 144)])
def test_lqr_schedules_on_the_angles_its_linearisation_depends_on(arm, scheduled, designs, lqr):
    """θ2…θN on a horizontal arm (θ1 is cyclic), and θ1 too in gravity; 24 points on one
    angle, 12 × 12 on two, one design on a single horizontal link."""
    law = lqr(arm)
    model = law.model
    assert law.scheduled == scheduled and law.gains.shape == (designs, model.n_joints,
                                                               2 * model.n)
    assert law.grid.shape == (designs, model.n_joints)
    unscheduled = [j for j in range(model.n_joints) if j not in scheduled]
    np.testing.assert_array_equal(law.grid[:, unscheduled], 0.0)
    # The gain does not depend on an angle that is not scheduled (θ1 of a horizontal arm).
    theta = RNG.uniform(-3, 3, model.n_joints)
    moved = theta.copy()
    moved[unscheduled] += 1.0
    np.testing.assert_array_equal(law.gain(theta), law.gain(moved))


@pytest.mark.parametrize("arm", ("three-link", "vertical-two-link"))
def test_lqr_sampled_loop_is_stable_at_its_design_points(arm, lqr):
    """Against scipy.signal's own ZOH of the model linearised about the operating point:
    every pole strictly inside the unit circle, at a few grid points spread over the
    schedule."""
    law = lqr(arm)
    for k in np.linspace(0, len(law.grid) - 1, 5).astype(int):
        A, B = law.model.linearize(*law.operating_point(law.grid[k]))
        Ad, Bd, *_ = scipy.signal.cont2discrete((A, B, np.eye(A.shape[0]), 0.0), TS, "zoh")
        radius = np.abs(np.linalg.eigvals(Ad - Bd @ law.gains[k])).max()
        # Measured ≤ 0.9999 (the slowest, structurally damped mode); round-off in the
        # eigenvalues of a ≤ 28×28 matrix is ~1e-13.
        assert radius < 1.0, (k, radius)


@pytest.mark.parametrize("arm", VERTICAL)
def test_lqr_operating_point_is_the_arm_at_rest_in_gravity(arm, lqr):
    """(Q0, τ0) at any joint angles: the model's acceleration there is nil up to the
    static deflection's three fixed-point steps (measured ≤ 3.6e-9 at the horizontal,
    ≤ 1.9e-4 over 200 random poses of the two-link arm: gravity's stiffness against the
    links' is not negligible everywhere); known bad: the undeflected arm held by the same
    torques, ≥ 1e-2."""
    law = lqr(arm)
    model = law.model
    n, N = model.n, model.n_joints
    for theta in (np.zeros(N), RNG.uniform(-3, 3, N)):
        Q0, tau0 = law.operating_point(theta)
        np.testing.assert_array_equal(Q0[:N], theta)
        at_rest = np.abs(model.acceleration(Q0, np.zeros(n), tau0)).max()
        assert at_rest < 1e-3, at_rest
        undeflected = np.zeros(n)
        undeflected[:N] = theta
        assert np.abs(model.acceleration(undeflected, np.zeros(n), tau0)).max() > 1e-2


def test_lqr_interpolates_multilinearly_on_two_angles(lqr):
    """Inside a cell of the three-link arm's 12 × 12 grid, K is the bilinear blend of the
    cell's four corners (by numpy, from `gains`), periodic in each angle."""
    law = lqr("three-link")
    G = 12
    table = law.gains.reshape(G, G, *law.gains.shape[1:])
    scale = np.abs(table).max()
    step = 2 * np.pi / G
    for _ in range(10):
        i, j = RNG.integers(G, size=2)
        f, g = RNG.uniform(0.01, 0.99, 2)
        theta = np.array([0.3, -np.pi + (i + f) * step, -np.pi + (j + g) * step])
        i1, j1 = (i + 1) % G, (j + 1) % G
        want = ((1 - f) * (1 - g) * table[i, j] + (1 - f) * g * table[i, j1]
                + f * (1 - g) * table[i1, j] + f * g * table[i1, j1])
        # The blend weights from (θ + π)·G/2π: round-off ~1e-15 of the largest gain.
        np.testing.assert_allclose(law.gain(theta), want, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(law.gain(theta + (0, 2 * np.pi, -2 * np.pi)), want, rtol=0,
                                   atol=1e-9 * scale)
    assert np.all(np.isnan(law.gain((0.0, 0.0, np.nan))))


@pytest.mark.parametrize("grid_points, message", [
    (3, "4..360"), ((12, 12, 12), "one per scheduled angle, 2"), (19, "361 designs")])
def test_lqr_refuses_a_grid_it_cannot_design(grid_points, message):
    with pytest.raises(ValueError, match=f"^grid_points.*{message}"):
        GainScheduledLQR(model_of("three-link"), Ts=TS, grid_points=grid_points)


# --- closed loops on the reduced plant -----------------------------------------------------------
def run(arm, controller, *, goal=None, nominal=None, duration=5.0):
    """A quintic move of the arm's joints from 0 to ``goal`` (default `GOAL`) in 2 s on the
    reduced plant, the true state fed back; {scenario key: value} ``nominal`` changes
    the arm the laws believe in."""
    N = named_arm(arm).n_links
    spec = {"arm": arm, "duration": duration, "controller": controller,
            "observer": {"kind": "none"}, "feedback": "true",
            "reference": {"kind": "quintic", "start": [0.0] * N,
                          "goal": list(GOAL[:N] if goal is None else goal), "move_time": 2.0}}
    if nominal:
        spec["nominal_params"] = nominal
    result = run_scenario(scenario_from_mapping(spec))
    assert result.status == "ok", result.message
    return result, N


def final_error(result, N) -> np.ndarray:
    """|θ − θ_d| of each joint at the end of the run [rad]."""
    return np.array([abs(result[f"theta{i}"][-1] - result[f"theta{i}_ref"][-1])
                     for i in range(1, N + 1)])


#: The largest |θ − θ_d| 3 s after the 2 s move ends (true state, reduced plant).
#: Measured (PD, CT, LQR) [rad]: single link 2.1e-11, 1.9e-11, 2.0e-13; rigid–flexible
#: 5.6e-16, 2.2e-11, 7.0e-14; three links 4.3e-9, 4.3e-8, 6.3e-10; vertical single link
#: 3.5e-4, 3.4e-4, 1.3e-13; vertical two links 9.5e-5, 1.6e-4, 6.3e-9 (the paper's arm:
#: 3.4e-5, 9.3e-4, 1.1e-5).  In gravity the PD and computed torque compensate the rigid
#: arm's gravity torque, not the sagging arm's: off the horizontal the difference over
#: K_p is their residual.  1e-3 rad clears every arm by ≥ 2.8×.
FINAL_ERROR = 1e-3


@pytest.mark.parametrize("law", ["pd", "ct", "lqr"])
@pytest.mark.parametrize("arm", EXAMPLE_ARMS)
def test_baselines_track_a_gentle_move_on_every_arm(arm, law):
    result, N = run(arm, {"kind": law})
    assert np.all(final_error(result, N) < FINAL_ERROR), final_error(result, N)


def test_the_tracking_bound_refuses_a_law_that_does_not_track():
    """Known bad: the PD with a hundredth of its default gains on the three-link arm."""
    pd = JointPD(model_of("three-link"), Ts=TS)
    result, N = run("three-link", {"kind": "pd", "options": {
        "kp": (pd.kp / 100).tolist(), "kd": (pd.kd / 100).tolist(), "feedforward": False}})
    assert np.any(final_error(result, N) > 10 * FINAL_ERROR), final_error(result, N)


#: The largest |θ| 3 s after the hold starts (arm straight out, horizontal): measured
#: PD/CT/LQR on the vertical single link 9.9e-14, 9.0e-14, 3.2e-17 rad (at the
#: horizontal the deflection does not change the joint's gravity torque), two links
#: 1.1e-5, 1.2e-5, 5.7e-8 (link 1's sag tilts link 2).  The issue's PBC bound.
HOLD_ERROR = 1e-4


@pytest.mark.parametrize("law", ["pd", "ct", "lqr"])
@pytest.mark.parametrize("arm", VERTICAL)
def test_baselines_hold_a_vertical_arm_against_gravity(arm, law):
    """Known bad: the same law believing the arm horizontal (nominal gravity 0)."""
    N = named_arm(arm).n_links
    result, _ = run(arm, {"kind": law}, goal=[0.0] * N)
    assert np.all(final_error(result, N) < HOLD_ERROR), final_error(result, N)
    blind, _ = run(arm, {"kind": law}, goal=[0.0] * N, nominal={"gravity": [0.0, 0.0]})
    assert np.any(final_error(blind, N) > 100 * HOLD_ERROR), final_error(blind, N)


@pytest.mark.parametrize("law", ["pd", "ct"])
@pytest.mark.parametrize("arm", VERTICAL)
def test_without_gravity_compensation_the_joints_sag_by_the_static_moment(arm, law):
    """gravity_compensation = false: the PD settles where K_p e = g_θ, computed torque
    where M_θθ K_p e = g_θ (e = θ_d − θ, g_θ the joints' static moment of the settled,
    sagging arm): to 1e-5 (measured ≤ 1.1e-6, still settling after 8 s).  Against the
    straight arm's static moment at the horizontal (the model's gravity force at Q = 0)
    within 2 %: measured 0.13 % (single link), 0.23 % (two links, PD) and 1.4 % (two
    links, computed torque: joint 2's (M⁻¹ g)₂ is a difference of terms 20× larger, so
    the 0.05 % the sag changes g₁ by shows 20×)."""
    model = model_of(arm)
    n, N = model.n, model.n_joints
    law_object = (JointPD if law == "pd" else RigidComputedTorque)(model, Ts=TS)
    result, _ = run(arm, {"kind": law, "options": {"gravity_compensation": False}},
                    goal=[0.0] * N, duration=8.0)
    sag = np.array([result[f"theta{i}_ref"][-1] - result[f"theta{i}"][-1]
                    for i in range(1, N + 1)])
    settled = np.array([result[name][-1] for name in model.coordinate_names])
    rigid = settled.copy()
    rigid[N:] = 0.0
    for Q, M_at, tolerance in ((settled, rigid, 1e-5), (np.zeros(n), np.zeros(n), 0.02)):
        g = model.gravity_force(Q)[:N]
        want = g / law_object.kp if law == "pd" else np.linalg.solve(
            model.mass_matrix(M_at)[:N, :N] * law_object.kp, g)
        np.testing.assert_allclose(sag, want, rtol=tolerance)
    assert np.all(np.abs(sag) > 10 * HOLD_ERROR)
