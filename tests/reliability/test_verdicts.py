"""No certificate is false and a verdict's evidence replays: the ν-gap against its
definition, computed independently; the falsifier's counterexample run again by `flexarm
run`; a law's output that is no torque refused; an STL `until` computed exactly and fast."""
import numpy as np
import control
import pytest
import scipy.optimize

from validation.verdicts.nugap import gap_detail

tf = control.tf


# --- the ν-gap by its definition -------------------------------------------------------------
def _mirrored(c: np.ndarray) -> np.ndarray:
    """The coefficients of c(−s) (highest power first)."""
    return c * (-1.0) ** np.arange(len(c) - 1, -1, -1)


def gap_by_definition(P1, P2) -> tuple[float, float, float | None]:
    """(δν, sup κ, winding number or None) of two SISO continuous plants n/d (coprime
    polynomials), by Vinnicombe's definition and no coprime factors of state-space models:

    - κ(ω) = |n1 d2 − n2 d1| / √((|n1|² + |d1|²)(|n2|² + |d2|²)) (the closed form, finite
      at the poles) on a dense grid — 10 points a 1e-4 decade, and 8000 points within
      ±10 % of each pole's magnitude down to 1e-9 of it — then every near-maximum refined
      by a bounded search;
    - the normalised factors are N = n/m, M = d/m with m Hurwitz, |m|² = |n|² + |d|² on the
      axis, so G2*G1 = q/(m2(−s) m1(s)) with q = n2(−s) n1(s) + d2(−s) d1(s), and the
      phase of a polynomial gains π for each root left of the axis and loses π for each one
      right of it as s runs up the axis: the winding number is (L − R − deg m1 + deg m2)/2
      from the roots of q, and a root on the axis (|Re| ≤ 1e-7 |root|: a crossing of
      κ = 1, simple, so its root is accurate to round-off) fails the condition;
    - δν = sup κ if the winding number is 0, else 1."""
    (n1, d1), (n2, d2) = [(np.asarray(P.num[0][0], float), np.asarray(P.den[0][0], float))
                          for P in (P1, P2)]

    def kappa(w):
        s = 1j * np.asarray(w, float)
        a1, b1, a2, b2 = (np.polyval(c, s) for c in (n1, d1, n2, d2))
        return np.abs(a1 * b2 - a2 * b1) / np.sqrt((abs(a1) ** 2 + abs(b1) ** 2)
                                                   * (abs(a2) ** 2 + abs(b2) ** 2))

    poles = np.abs(np.concatenate([np.roots(d1), np.roots(d2)]))
    offsets = np.concatenate([-np.logspace(-9, -1, 4001), np.logspace(-9, -1, 4001)])
    w = np.unique(np.concatenate([[0.0], np.logspace(-6, 6, 120_001), poles,
                                  np.outer(poles, 1 + offsets).ravel()]))
    k = kappa(w)
    peak = float(k.max())
    local = (k >= np.roll(k, 1)) & (k >= np.roll(k, -1)) & (k >= peak - 1e-3)
    for i in np.flatnonzero(local):
        a, b = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
        res = scipy.optimize.minimize_scalar(lambda x: -kappa([x])[0], bounds=(a, b),
                                             method="bounded", options={"xatol": 1e-14 * b})
        peak = max(peak, -float(res.fun))
    q = np.polyadd(np.polymul(_mirrored(n2), n1), np.polymul(_mirrored(d2), d1))
    roots = np.roots(np.trim_zeros(q, "f"))
    if np.any(np.abs(roots.real) <= 1e-7 * np.maximum(np.abs(roots), 1.0)):
        return 1.0, peak, None
    winding = (np.sum(roots.real < 0) - np.sum(roots.real > 0) - (len(d1) - 1)
               + (len(d2) - 1)) / 2
    return (peak if winding == 0 else 1.0), peak, winding


W6 = 2 * np.pi * 6  # the arm's first flexible mode, 6 Hz [rad/s]


def rigid_and_mode(w, zeta=0.0, gain=0.5):
    """1/s² + gain/(s² + 2ζωs + ω²): a rigid body with one flexible mode."""
    return tf(1, [1, 0, 0]) + tf(gain, [1, 2 * zeta * w, w ** 2])


# (name, P1, P2): the pair of issue 32, more flexible pairs, and the SISO pairs of the
# ν-gap's own tests (tests/test_nugap.py).
PAIRS = [
    ("issue 32: undamped mode 2 % apart", rigid_and_mode(W6), rigid_and_mode(1.02 * W6)),
    ("undamped mode, gains 0.5 and 0.6", rigid_and_mode(W6, 0, 0.5), rigid_and_mode(W6, 0, 0.6)),
    ("ζ = 0.02, 2 % apart", rigid_and_mode(W6, 0.02), rigid_and_mode(1.02 * W6, 0.02)),
    ("ζ = 0.05, 20 % apart", rigid_and_mode(W6, 0.05), rigid_and_mode(1.2 * W6, 0.05)),
    ("ζ = 0.01, gains 0.5 and 0.6", rigid_and_mode(W6, 0.01, 0.5),
     rigid_and_mode(W6, 0.01, 0.6)),
    ("600 Hz, ζ = 0.001, 1.7 % apart", rigid_and_mode(2 * np.pi * 600, 0.001),
     rigid_and_mode(2 * np.pi * 610, 0.001)),
    ("matlab second order", tf([1, 2], [1, 5, 10]), tf([1, 1], [1, 3, 10])),
    ("matlab unstable/stable", tf(1, [1, -0.001]), tf(1, [1, 0.001])),
    ("P and 2P", tf(1, [1, 1]), tf(2, [1, 1])),
    ("rigid bodies", tf(1, [1, 0, 0]), tf(1, [2, 0, 0])),
    ("k/(s+1) vs k/(s-1), k = 2", tf(2, [1, 1]), tf(2, [1, -1])),
    ("k/(s+1) vs k/(s-1), k = 0.5 (winding 1)", tf(0.5, [1, 1]), tf(0.5, [1, -1])),
    ("far pole", tf(1, [1, 1]), tf(1, [0.01, 1.01, 1])),
    ("non-minimum phase", tf([-1, 1], [1, 2, 1]), tf([-1.2, 1], [1, 2, 1])),
]


@pytest.mark.parametrize("name, P1, P2", PAIRS, ids=[p[0] for p in PAIRS])
def test_nu_gap_is_its_definition(name, P1, P2):
    """Known-bad (issue 32): the first pair gave 9.0e-11, a certificate for any loop with
    a margin above it, where the definition gives 1 (κ reaches 1 between the two modes,
    so det(G2*G1) vanishes on the axis)."""
    expected, peak, winding = gap_by_definition(P1, P2)
    detail = gap_detail(P1, P2)
    assert (detail.winding == 0) == (winding == 0)
    # 1e-11: κ from the state-space factors and from the closed form differ by ≤ 6e-13
    # (measured next to the undamped poles, ≤ 1e-15 elsewhere); both searches refine their
    # peaks to far less than that.
    assert detail.value == pytest.approx(expected, abs=1e-11)
    if winding is not None:  # where κ reaches 1, the peak is wherever the search lands
        assert detail.peak == pytest.approx(peak, abs=1e-11)


def test_an_observable_mode_is_kept_and_a_hidden_one_removed():
    """Known-good of the hidden-mode test: the issue's plant with an extra undamped mode
    that its output does not see (it would leave the Riccati equation without a
    stabilising solution) is at the same distance as the plant itself; the 6 Hz mode, seen
    by the output, stays (the first case above)."""
    P1 = control.ss(rigid_and_mode(W6))
    hidden = control.ss([[0.0, 10.0], [-10.0, 0.0]], [[0.0], [1.0]], [[0.0, 0.0]], 0.0)
    with_hidden = control.parallel(P1, hidden)
    assert with_hidden.nstates == P1.nstates + 2
    P2 = rigid_and_mode(W6, 0.0, 0.6)
    # 1e-12: the same factors up to the round-off of a different realisation (measured
    # 3e-13; kept, the hidden mode makes the factorisation fail).
    assert gap_detail(with_hidden, P2).value == pytest.approx(gap_detail(P1, P2).value,
                                                              abs=1e-12)
