"""Linear models of both plants, the laws linearised from their objects, and the sampled
loop, against independent references: Exudyn's modal analysis, an open-loop Exudyn run,
the model's exact linearisation, the laws' own gains, python-control's feedback."""
import control
import numpy as np
import pytest

from controllers import GainScheduledLQR, JointPD, PaperReference, PassivityBasedController
from plant_exudyn import ExudynPlant, Mesh, linear_model, natural_frequencies
from reduced_model import ArmModel, ArmParameters, named_arm
from validation import law_gain, reduced_linear_model
from validation.verdicts.linear import (NotLinearisable, closed_loop_matrix, growth_rate,
                                        largest_stable_period)


def hold(theta):
    """A reference resting at ``theta``."""
    return lambda t: (np.asarray(theta, float), np.zeros(2), np.zeros(2))


@pytest.mark.parametrize("params", [ArmParameters(), named_arm("table1")],
                         ids=["default", "table1"])
@pytest.mark.parametrize("theta", [(0.0, 0.0), (0.3, 1.2)])
def test_fe_linearisation_has_the_fe_natural_frequencies(params, theta):
    P = linear_model(params, Mesh(), theta=theta)
    k = P.nstates // 2
    omega2 = -np.diag(P.A[k:, :k])  # the states are the FE modes: A = [[0, I], [−Ω², −D]]
    f = np.sort(np.sqrt(omega2)) / (2 * np.pi)
    reference = natural_frequencies(params, Mesh(), theta=theta, joints="free", n=6)
    assert np.all(f[:2] == 0.0)  # the two rigid-body modes, exactly (module docstring)
    # The bound, 1e-6 relative; measured ≤ 3e-9 (two projections of one Jacobian).
    np.testing.assert_allclose(f[2:8], reference, rtol=1e-6)


def test_fe_step_response_matches_an_open_loop_exudyn_run():
    """From rest at θ = (0.3, 0.7), constant small torques for 0.5 s: the linear model's
    response against the truth plant's (step 0.1 ms, so its time-step error ~1e-4 is far
    below the bound).  θ moves by ~1e-3 rad, so the nonlinearity is ~1e-3 relative."""
    params, theta, tau = ArmParameters(), (0.3, 0.7), np.array([0.02, 0.01])
    P = linear_model(params, Mesh(), theta=theta)
    plant = ExudynPlant(params, mesh=Mesh(), step=1e-4)
    x0 = np.zeros(plant.state_size)
    x0[:2] = theta
    plant.reset(x0)
    t = np.arange(0.0, 0.5 + 1e-12, 1e-3)
    m = plant.state_size // 2
    truth = []
    for _ in t[1:]:
        plant.step(tau)
        v = plant.truth_vector()
        truth.append(np.concatenate([v[:2 * m], v[2 * m + 4:2 * m + 6]]))
    truth = np.array(truth) - np.concatenate([x0, [0.0, 0.0]])
    linear = control.forced_response(P, t, np.tile(tau[:, None], len(t))).outputs.T[1:]
    names = list(P.output_labels)
    # θ, q, θ̇ and the tip deflections; 1 % of each signal's peak (the bound).
    # Measured: ≤ 0.44 % (q22, 0.3 µm); the modal rates of the stiff modes q̇12…q̇22,
    # whose peaks are 0.02–5 mm/s, differ by up to 1.2 % and are not judged.
    for name in ("theta1", "theta2", "q11", "q12", "q21", "q22", "theta1_dot", "theta2_dot",
                 "tip_defl1", "tip_defl2"):
        i = names.index(name)
        peak = np.abs(truth[:, i]).max()
        assert np.abs(linear[:, i] - truth[:, i]).max() <= 0.01 * peak, name


def test_reduced_state_space_is_the_models_linearisation():
    model = ArmModel(ArmParameters())
    Q0 = np.zeros(model.n)
    Q0[:2] = (0.2, 0.9)
    A, B = model.linearize(Q0)
    P = reduced_linear_model(model, theta=(0.2, 0.9))
    np.testing.assert_array_equal(P.A, A)
    np.testing.assert_array_equal(P.B, B)
    assert list(P.state_labels) == list(model.state_names)
    assert list(P.input_labels) == ["tau1", "tau2"]
    # The tip deflection rows read w_i(L) = φ_i(L)·q_i.
    q = np.random.default_rng(0).normal(size=model.n - 2) * 1e-3
    x = np.zeros(2 * model.n)
    x[2:model.n] = q
    tips = P.C[[P.output_labels.index("tip_defl1"), P.output_labels.index("tip_defl2")]] @ x
    Q = Q0.copy()
    Q[2:] = q
    np.testing.assert_allclose(tips, model.tip_deflection(Q), rtol=1e-12)
    # Discrete: the exact ZOH of the same system.
    Pd = reduced_linear_model(model, theta=(0.2, 0.9), Ts=1e-3)
    np.testing.assert_allclose(Pd.A, control.sample_system(P, 1e-3).A, rtol=0, atol=1e-14)


def test_reduced_and_fe_models_share_their_outputs():
    model = ArmModel(ArmParameters())
    red = reduced_linear_model(model)
    fe = linear_model(ArmParameters(), Mesh(), model=model)
    assert list(red.output_labels) == list(fe.output_labels)
    # Their static rigid-body response agrees: the high-frequency mobility of θ̇ (the
    # Markov parameter C_θ̇ B) is the joint block of M⁻¹: 91 on the reduced model and 101
    # on the FE arm for joint 2 (the FE modes above the 2+2 model carry the
    # difference), ~1 for joint 1.
    rows = [red.output_labels.index("theta1_dot"), red.output_labels.index("theta2_dot")]
    mob_red = (red.C @ red.B)[rows]
    mob_fe = (fe.C @ fe.B)[rows]
    assert mob_red[1, 1] == pytest.approx(91.19, rel=1e-3)
    assert mob_fe[1, 1] == pytest.approx(101, rel=0.02)


# --- the laws linearised from their objects ------------------------------------------------------
def test_pd_gain_is_its_own_gains():
    model = ArmModel(ArmParameters())
    pd = JointPD(model, Ts=1e-3, kp=(30.0, 15.0), kd=(18.1, 8.2))
    x = np.zeros(2 * model.n)
    x[:2] = (0.4, -0.3)
    K = law_gain(pd, x, 1.0, PaperReference())
    expected = np.zeros((2, 2 * model.n))
    expected[:, :2] = np.diag([30.0, 15.0])
    expected[:, model.n:model.n + 2] = np.diag([18.1, 8.2])
    np.testing.assert_allclose(K, expected, atol=1e-7)  # central differences of a linear law


def test_pbc_gain_holds_the_flexible_rate_feedback_of_eq_20():
    """At a resting point of the reference (v = 0), ∂τ/∂q̇ of eq. (20) rows 0–1 is
    −M_θq Λ_f (the term M v̇ with v̇ = −Λ ė): K's q̇ columns are M_θq Λ_f — the gain the
    old 2/λmax(W G) prediction left out."""
    model = ArmModel(ArmParameters())
    pbc = PassivityBasedController(model, Ts=1e-3, lambda_flex=(1.0, 2.0, 0.5, 3.0))
    x = np.zeros(2 * model.n)
    x[:2] = (0.1, 0.8)
    K = law_gain(pbc, x, 0.0, hold(x[:2]))
    M = model.mass_matrix(x[:model.n])
    n = model.n
    np.testing.assert_allclose(K[:, n + 2:], M[:2, 2:] @ np.diag([1.0, 2.0, 0.5, 3.0]),
                               rtol=1e-6, atol=1e-9)
    # The joint rate gains: M_θθ Λ_θ + K_v.
    np.testing.assert_allclose(K[:, n:n + 2], M[:2, :2] @ np.diag([3.0, 3.0]) +
                               np.diag([10.0, 5.0]), rtol=1e-6)


def test_lqr_gain_round_trip_through_python_control():
    """The issue's round trip: `control.feedback` of the exported ZOH reduced model with the
    LQR's gain has the eigenvalues of our own closed-loop analysis (to 1e-9)."""
    model = ArmModel(ArmParameters())
    lqr = GainScheduledLQR(model, Ts=1e-3)
    theta = lqr.grid[7]  # a grid point: the design's own gain, no interpolation
    theta2 = float(theta[1])
    x = np.zeros(2 * model.n)
    x[:2] = theta
    K = law_gain(lqr, x, 0.0, hold(x[:2]))
    # Our linearisation reads the law's own gain (central differences of a law linear in
    # x: 1e-7 relative is their round-off).
    np.testing.assert_allclose(K, lqr.gain(theta), rtol=1e-7, atol=1e-7 * np.abs(K).max())
    P = reduced_linear_model(model, theta=(0.0, theta2), Ts=1e-3)[list(model.state_names), :]
    ours = np.linalg.eigvals(closed_loop_matrix(P, K, model.state_names))
    theirs = control.feedback(P, K).poles()
    key = lambda z: (round(z.real, 6), round(z.imag, 6))  # noqa: E731
    np.testing.assert_allclose(sorted(ours, key=key), sorted(theirs, key=key), rtol=0,
                               atol=1e-9)
    assert np.abs(ours).max() < 1  # the design is stable at its Ts by construction


def test_a_sign_law_is_not_linearisable():
    class Bang:
        def __call__(self, t, x, ref):
            return np.sign(ref(t)[0] - x[:2])
    x = np.zeros(12)
    with pytest.raises(NotLinearisable):
        law_gain(Bang(), x, 0.0, hold((0.0, 0.0)))


def test_largest_stable_period_of_a_sampled_rate_loop():
    """ẋ = u/J, u = −k x sampled with a ZOH: x_{k+1} = (1 − k Ts/J) x_k, stable iff
    Ts < 2J/k.  "Stable" allows growth up to 0.01 s⁻¹ (`STABLE_GROWTH`), which moves the
    limit by 0.01·Ts/2 = 1.3e-4 relative here."""
    J, k = 0.5, 40.0
    P = control.ss(0.0, 1.0 / J, 1.0, 0.0, outputs=["v"])

    def growth(Ts):
        return growth_rate(closed_loop_matrix(control.sample_system(P, Ts), np.array([[k]]),
                                              ["v"]), Ts)
    assert largest_stable_period(growth, rtol=1e-6) == pytest.approx(2 * J / k, rel=2e-4)
