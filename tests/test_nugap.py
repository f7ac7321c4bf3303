"""The ν-gap and the stability margin against published values, closed forms and an
independent algorithm (SLICOT's H∞ norm), and the properties of a metric."""
import math

import control
import numpy as np
import pytest

from validation import nu_gap, stability_margin
from validation.verdicts import graphs
from validation.verdicts.nugap import gap_detail, margin_detail

tf = control.tf


def brute_force_siso(P1, P2, *, decades=(-6, 6), points=400_000) -> float:
    """sup κ of two SISO plants by the closed form κ = |P1 − P2| / √((1+|P1|²)(1+|P2|²))
    on a dense grid: no coprime factors, no refinement — an independent computation."""
    w = np.concatenate([[0.0], np.logspace(*decades, points)])
    a, b = P1(1j * w), P2(1j * w)
    return float(np.max(np.abs(a - b) / np.sqrt((1 + np.abs(a) ** 2) * (1 + np.abs(b) ** 2))))


def rotation(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def mimo(Pa, Pb, U, V):
    """U diag(Pa, Pb) Vᵀ as a state-space system (U, V orthogonal: δν is invariant)."""
    diag = control.append(control.ss(Pa), control.ss(Pb))
    return control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), U) * diag * \
        control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), V.T)


MATLAB_PAIR = (tf([1, 2], [1, 5, 10]), tf([1, 1], [1, 3, 10]))

# (name, P1, P2, expected δν, tolerance, where the number comes from)
PANEL = [
    # MATLAB gapmetric documentation: 1/(s − 0.001) vs 1/(s + 0.001), nugap = 0.0020; the
    # closed form is 2a/(1 + a²) at ω = 0 (a = 0.001), so the printed digits are checked
    # and the closed form to 1e-9.
    ("matlab unstable/stable", tf(1, [1, -0.001]), tf(1, [1, 0.001]), 0.002 / (1 + 1e-6), 1e-9),
    # MATLAB gapmetric documentation ("gap metric and stability margin"): nugap = 0.1390.
    ("matlab second order", *MATLAB_PAIR, 0.1390, 1e-3),
    # P and 2P: κ = |1 − c||P| / √((1 + |P|²)(1 + c²|P|²)) peaks where |P|² = 1/c at
    # |1 − c|/(1 + c) = 1/3 (|1/(s + 1)|² = 1/2 at ω = 1).
    ("P and 2P", tf(1, [1, 1]), tf(2, [1, 1]), 1 / 3, 1e-9),
    # Rigid bodies 1/(J s²), J = 1 and 2: κ peaks at |a − b|/(a + b) = 1/3 (a = 1/J).
    ("rigid bodies", tf(1, [1, 0, 0]), tf(1, [2, 0, 0]), 1 / 3, 1e-9),
    # The same at the double pole z = 1 (ZOH at 10 ms): still P and P/2, still 1/3 (the
    # factors are accurate to ~1e-8 at z = 1).
    ("rigid bodies, ZOH", control.c2d(tf(1, [1, 0, 0]), 0.01), control.c2d(tf(1, [2, 0, 0]), 0.01),
     1 / 3, 1e-6),
    # Discrete P and 2P (|0.5/(z − 0.5)|² = 1/2 is reached on the circle): 1/3.
    ("discrete P and 2P", tf(0.5, [1, -0.5], 0.1), tf(1, [1, -0.5], 0.1), 1 / 3, 1e-9),
    # The winding number condition holds for k = 2 (see the failing k = 0.5 below):
    # κ = 2k/(ω² + 1 + k²) peaks at ω = 0 at 2k/(1 + k²) = 0.8.
    ("k/(s+1) vs k/(s-1), k = 2", tf(2, [1, 1]), tf(2, [1, -1]), 0.8, 1e-9),
    # MIMO: rotations of diag(MATLAB pair, P and 1.25P): max(0.1390, 0.25/2.25).
    ("MIMO rotated diagonal",
     mimo(MATLAB_PAIR[0], tf(1, [1, 1]), rotation(0.3), rotation(-1.1)),
     mimo(MATLAB_PAIR[1], tf(1.25, [1, 1]), rotation(0.3), rotation(-1.1)), 0.1390, 1e-3),
]


@pytest.mark.parametrize("name, P1, P2, expected, tol", PANEL, ids=[p[0] for p in PANEL])
def test_panel(name, P1, P2, expected, tol):
    assert nu_gap(P1, P2) == pytest.approx(expected, abs=tol)


def test_published_digits_of_the_matlab_examples():
    # As printed by MATLAB (4 decimals): 0.0020 and 0.1390.
    assert round(nu_gap(tf(1, [1, -0.001]), tf(1, [1, 0.001])), 4) == 0.0020
    assert round(nu_gap(*MATLAB_PAIR), 4) == 0.1390


@pytest.mark.parametrize("P1, P2", [MATLAB_PAIR, (tf(1, [1, 1]), tf(1, [0.01, 1.01, 1]))],
                         ids=["matlab second order", "far pole"])
def test_agrees_with_a_dense_closed_form_grid(P1, P2):
    # The far pole (P/(0.01 s + 1)) has no published value: the brute-force grid of 4e5
    # points is the independent reference (both plants stable and minimum phase: the
    # winding condition holds).  1e-3 is the bound; measured agreement ~1e-8.
    assert nu_gap(P1, P2) == pytest.approx(brute_force_siso(P1, P2), abs=1e-3)


def test_a_plant_is_at_distance_zero_from_itself():
    # κ(P, P) = σ(G(I − G*G)): the factors' departure from inner, ≤ 5e-13 measured except
    # at the ZOH double pole z = 1 (5e-8).
    for _, P1, P2, _, _ in PANEL:
        assert nu_gap(P1, P1) < 1e-6
        assert nu_gap(P2, P2) < 1e-6


@pytest.mark.parametrize("name, P1, P2, expected, tol", PANEL, ids=[p[0] for p in PANEL])
def test_symmetric(name, P1, P2, expected, tol):
    # Each direction uses the other plant's factors: agreement to their accuracy (measured
    # ≤ 1e-11, and 3e-9 at the ZOH double pole z = 1).
    assert nu_gap(P1, P2) == pytest.approx(nu_gap(P2, P1), abs=1e-6)


def test_winding_condition_failure_gives_one():
    """k = 0.5: the chordal distance peaks at 0.8, but the winding number of det(G2*G1) is
    1 (derivation: 1 + P2~P1 = 1 − k²/(s + 1)² has no zero in the right half plane, while
    P2 has one unstable pole).  δν must be 1: C = 0 stabilises P1 with b = 1/√(1 + k²) =
    0.894 > 0.8, and does not stabilise P2."""
    P1, P2 = tf(0.5, [1, 1]), tf(0.5, [1, -1])
    detail = gap_detail(P1, P2)
    assert detail.peak == pytest.approx(0.8, abs=1e-9)
    assert detail.winding != 0
    assert detail.value == 1.0
    assert stability_margin(P1, 0.0) == pytest.approx(1 / math.sqrt(1.25), abs=1e-9)
    assert stability_margin(P2, 0.0) == 0.0


def test_doubling_the_grid_changes_little():
    # The bound: < 1e-3.  Peaks are refined, so measured changes are ~1e-12.
    for _, P1, P2, _, _ in PANEL:
        assert abs(nu_gap(P1, P2, points_per_decade=60)
                   - nu_gap(P1, P2, points_per_decade=120)) < 1e-3


# --- the stability margin ---------------------------------------------------------------------
@pytest.mark.parametrize("P, C, expected", [
    (tf(4, [1, -0.001]), 1.0, 0.7069),   # MATLAB ncfmargin documentation, low gain
    (tf(4, [1, -0.001]), 10.0, 0.0995),  # the same, high gain
    (MATLAB_PAIR[0], tf(4.4, [1, 0]), 0.1961),  # MATLAB gapmetric documentation
])
def test_margin_against_published_values(P, C, expected):
    # Published to 4 decimals.
    assert stability_margin(P, C) == pytest.approx(expected, abs=1e-4)


def test_margin_closed_form_for_a_static_siso_loop():
    # b = min_ω |1 + PC| / √((1 + |P|²)(1 + |C|²)) for SISO; dense grid as reference.
    P, C = tf(3, [1, 2, 5]), 0.7
    w = np.concatenate([[0.0], np.logspace(-4, 4, 200_000)])
    p = P(1j * w)
    expected = np.min(np.abs(1 + p * C) / np.sqrt((1 + np.abs(p) ** 2) * (1 + C ** 2)))
    assert stability_margin(P, C) == pytest.approx(expected, abs=1e-6)


def test_the_certificate_holds_on_the_matlab_example():
    """MATLAB's example: b(P1, C) = 0.1961 > δν(P1, P2) = 0.1390, so C stabilises P2."""
    P1, P2 = MATLAB_PAIR
    C = tf(4.4, [1, 0])
    assert nu_gap(P1, P2) < stability_margin(P1, C)
    assert margin_detail(P2, C).stable


def test_certificate_soundness_on_random_loops():
    """Whenever δν(P1, P2) < b(P1, C), C stabilises P2 (Vinnicombe's theorem): checked on
    random second-order plants with random lead-lag controllers, continuous and ZOH."""
    rng = np.random.default_rng(7)
    certified = 0
    for _ in range(40):
        wn, zeta, k = rng.uniform(0.5, 5), rng.uniform(0.01, 0.7), rng.uniform(0.5, 3)
        P1 = tf(k * wn ** 2, [1, 2 * zeta * wn, wn ** 2])
        P2 = tf(k * rng.uniform(0.7, 1.4) * wn ** 2,
                [1, 2 * zeta * rng.uniform(0.3, 1.5) * wn, (wn * rng.uniform(0.8, 1.2)) ** 2])
        C = tf([rng.uniform(0.1, 2), rng.uniform(0.1, 2)], [1, rng.uniform(0.5, 5)])
        for Ts in (None, 0.05):
            a, b, c = (P1, P2, C) if Ts is None else (control.c2d(P1, Ts), control.c2d(P2, Ts),
                                                     control.c2d(C, Ts))
            if nu_gap(a, b) < stability_margin(a, c):
                certified += 1
                assert margin_detail(b, c).stable
    assert certified >= 10  # the check is not vacuous


# --- an FE-sized MIMO pair against SLICOT's H∞ norm ---------------------------------------------
@pytest.fixture(scope="module")
def arm_loop_pair():
    """The PBC's loop at the plant input, reduced model vs FE arm (72 states), ZOH 1 ms."""
    from controllers import PassivityBasedController
    from plant_exudyn import linear_model
    from reduced_model import ArmModel, ArmParameters
    from validation.verdicts.linear import law_gain, reduced_linear_model
    model = ArmModel(ArmParameters())
    names = list(model.state_names)
    x = np.zeros(12)
    x[1] = 0.5
    K = law_gain(PassivityBasedController(model, Ts=1e-3), x, 0.0,
                 lambda t: (x[:2].copy(), np.zeros(2), np.zeros(2)))
    gain = control.ss(np.zeros((0, 0)), np.zeros((0, 12)), np.zeros((2, 0)), K)
    red = reduced_linear_model(model, theta=(0.0, 0.5))[names, :]
    fe = linear_model(ArmParameters(), theta=(0.0, 0.5), model=model)[names, :]
    return gain * control.sample_system(red, 1e-3), gain * control.sample_system(fe, 1e-3)


def _factors(P, discrete):
    G = graphs.graph_symbol(graphs.prepared(P, discrete), discrete)
    return control.ss(*G.matrices, P.dt)


def test_sup_of_the_chordal_distance_matches_slicot_hinf_norm(arm_loop_pair):
    """sup κ = ‖G̃2 G1‖∞ with G̃2 = [−M̃2, Ñ2] the left factors of P2 (the transposed
    right factors of P2ᵀ): a stable product whose H∞ norm SLICOT's ab13dd computes
    without any frequency grid (Hamiltonian bisection)."""
    P1, P2 = arm_loop_pair
    G1 = _factors(P1, True)
    Gt = _factors(control.ss(P2.A.T, P2.C.T, P2.B.T, P2.D.T, P2.dt), True)
    p = P1.noutputs
    A, B, C, D = Gt.A, Gt.B, Gt.C, Gt.D  # [N'; M'] of P2ᵀ: rows 0..m-1 N', then M'
    m_rows = P2.ninputs
    N_, M_ = slice(0, m_rows), slice(m_rows, m_rows + p)
    left = control.ss(A.T, np.hstack([-C[M_].T, C[N_].T]), B.T,
                      np.hstack([-D[M_].T, D[N_].T]), P1.dt)
    psi = left * G1
    norm, _ = control.linfnorm(psi, tol=1e-8)
    detail = gap_detail(P1, P2)
    assert detail.winding == 0
    assert detail.value == pytest.approx(norm, abs=1e-3)  # the bound


def test_fe_sized_pair_properties(arm_loop_pair):
    P1, P2 = arm_loop_pair
    d12 = nu_gap(P1, P2)
    assert nu_gap(P1, P1) < 1e-6  # 72 states: the factorisation's round-off
    assert nu_gap(P2, P1) == pytest.approx(d12, abs=1e-6)
    assert abs(nu_gap(P1, P2, points_per_decade=120) - d12) < 1e-3


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="same inputs and outputs"):
        nu_gap(tf(1, [1, 1]), control.ss(control.append(tf(1, [1, 1]), tf(1, [1, 2]))))
    with pytest.raises(ValueError, match="continuous or all discrete"):
        nu_gap(tf(1, [1, 1]), tf(1, [1, 0.5], 0.1))
    with pytest.raises(ValueError, match="map the 1 outputs"):
        stability_margin(tf(1, [1, 1]), np.ones((2, 1)))
