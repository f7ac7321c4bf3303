"""The exact hold's compiled update (`_hold.ExactHold`): the constrained acceleration
response W B(q) Δf with the entries of C and B that follow the configuration (ANCF slopes,
rigid bodies' rotations) set from q, the stuck friction bristles held as constraints, and
the shifts of the step's start (`_hold`'s module docstring)."""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.experimental import structref

__all__ = ["HoldData", "new_hold_data", "response_into", "restart"]

_V, _M = types.Array(types.float64, 1, "C"), types.Array(types.float64, 2, "C")
_MI = types.Array(types.int64, 2, "C")
_FIELDS = (("minv", _M), ("C", _M), ("c_cols", _MI), ("Bt", _M), ("b_cols", _MI),
           ("c_rows", _M), ("b_rows", _M), ("slopes", _MI), ("slope_ref", _M),
           ("c_rot", _M), ("b_rot", _M), ("factors", _V), ("y", _V), ("G", _M), ("S", _M), ("z", _V), ("delta", _V),
           ("change", _V), ("sticks", _MI), ("stick_law", _M), ("stick_response", _M))


@structref.register
class _HoldDataType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class HoldData(structref.StructRefProxy):
    """What `restart` works with: M⁻¹, C and the load matrix with their patterns and
    slope- and rotation-dependent entries, the step's factors, the friction bristles (`ExactHold`'s
    ``sticks``: indices, then stiffness, damping, level) and the work arrays (one
    structure passed by reference: 19 separate arrays cost ~5 µs a call to unbox)."""

    @property
    def change(self):
        return _change(self)


@njit(cache=True)
def _change(d):
    return d.change


structref.define_boxing(_HoldDataType, HoldData)
_HOLD = _HoldDataType(_FIELDS)


@njit(cache=True)
def new_hold_data(minv, C, c_cols, Bt, b_cols, c_rows, b_rows, slopes, slope_ref, c_rot,
                  b_rot, factors, y, G, S, z, delta, change, sticks, stick_law,
                  stick_response):
    """A `HoldData` of these arrays (shared, not copied)."""
    d = structref.new(_HOLD)
    d.minv, d.C, d.c_cols, d.Bt, d.b_cols = minv, C, c_cols, Bt, b_cols
    d.c_rows, d.b_rows, d.slopes, d.slope_ref, d.factors = (c_rows, b_rows, slopes,
                                                            slope_ref, factors)
    d.c_rot, d.b_rot = c_rot, b_rot
    d.y, d.G, d.S, d.z, d.delta, d.change = y, G, S, z, delta, change
    d.sticks, d.stick_law, d.stick_response = sticks, stick_law, stick_response
    return d


@njit(cache=True)
def _set_slope_entries(matrix, rows, slopes, slope_ref, q):
    """Each slope-dependent pair of ``matrix`` (row, node, coefficient) from the slope in
    ``q``: coefficient × (−s_y, s_x)/|s|²."""
    for e in range(rows.shape[0]):
        row, k, coef = int(rows[e, 0]), int(rows[e, 1]), rows[e, 2]
        ix, iy = slopes[k, 0], slopes[k, 1]
        sx, sy = slope_ref[k, 0] + q[ix], slope_ref[k, 1] + q[iy]
        s2 = sx * sx + sy * sy
        matrix[row, ix], matrix[row, iy] = -coef * sy / s2, coef * sx / s2


@njit(cache=True)
def _set_rotation_entries(matrix, rows, q):
    """Each rotation-dependent entry of ``matrix`` (row, column, K, A, B, reference) from
    the angle in ``q``: K + A cos φ + B sin φ, φ = reference + q[column]."""
    for e in range(rows.shape[0]):
        row, col = int(rows[e, 0]), int(rows[e, 1])
        phi = rows[e, 5] + q[col]
        matrix[row, col] = rows[e, 2] + rows[e, 3] * np.cos(phi) + rows[e, 4] * np.sin(phi)


@njit(cache=True)
def _factor(d):
    """G = C M⁻¹ and S = C M⁻¹ Cᵀ = L Lᵀ (L in S's lower triangle), C as last set."""
    minv, C, c_cols, G, S = d.minv, d.C, d.c_cols, d.G, d.S
    n, m = minv.shape[0], C.shape[0]
    for r in range(m):  # row r of G: C's few entries of row r
        G[r, :] = 0.0
        for c in c_cols[r]:
            if c >= 0:
                w = C[r, c]
                for i in range(n):
                    G[r, i] += w * minv[c, i]
    for r in range(m):  # S = G Cᵀ (symmetric positive definite)
        for t in range(r + 1):
            acc = 0.0
            for c in c_cols[t]:
                if c >= 0:
                    acc += G[r, c] * C[t, c]
            S[r, t] = acc
    for r in range(m):
        for t in range(r + 1):
            acc = S[r, t]
            for k in range(t):
                acc -= S[r, k] * S[t, k]
            S[r, t] = np.sqrt(acc) if t == r else acc / S[t, t]


@njit(cache=True)
def _project(d, y, out):
    """``out`` = y − Gᵀ S⁻¹ C y: the constrained response to the load whose unconstrained
    response is y = M⁻¹ f (`_factor` done)."""
    C, c_cols, G, S, z = d.C, d.c_cols, d.G, d.S, d.z
    n, m = y.shape[0], C.shape[0]
    for r in range(m):  # z = C y, then S⁻¹ z
        acc = 0.0
        for c in c_cols[r]:
            if c >= 0:
                acc += C[r, c] * y[c]
        z[r] = acc
    for r in range(m):
        acc = z[r]
        for k in range(r):
            acc -= S[r, k] * z[k]
        z[r] = acc / S[r, r]
    for r in range(m - 1, -1, -1):
        acc = z[r]
        for k in range(r + 1, m):
            acc -= S[k, r] * z[k]
        z[r] = acc / S[r, r]
    for i in range(n):
        out[i] = y[i]
    for r in range(m):
        for i in range(n):
            out[i] -= G[r, i] * z[r]


@njit(cache=True)
def constrained_response(d, out):
    """``out`` = W B ``d.change`` (module docstring), C and B as last set."""
    minv, Bt, b_cols, change, y = d.minv, d.Bt, d.b_cols, d.change, d.y
    n = minv.shape[0]
    y[:] = 0.0  # y = M⁻¹ B change, from B's few non-zero entries (M⁻¹ symmetric)
    for j in range(Bt.shape[0]):
        if change[j] != 0.0:
            for c in b_cols[j]:
                if c >= 0:
                    w = Bt[j, c] * change[j]
                    for i in range(n):
                        y[i] += w * minv[c, i]
    _factor(d)
    _project(d, y, out)


@njit(cache=True)
def response_into(d, q, out):
    """``out`` = W B(q) ``d.change``: C's and B's slope- and rotation-dependent entries
    set from ``q``, then `constrained_response`."""
    _set_slope_entries(d.C, d.c_rows, d.slopes, d.slope_ref, q)
    _set_slope_entries(d.Bt, d.b_rows, d.slopes, d.slope_ref, q)
    _set_rotation_entries(d.C, d.c_rot, q)
    _set_rotation_entries(d.Bt, d.b_rot, q)
    constrained_response(d, out)


@njit(cache=True)
def _relative(x, base, moving):
    """A bristle's relative coordinate in ``x`` (base −1: the ground)."""
    return x[moving] - (x[base] if base >= 0 else 0.0)


@njit(cache=True)
def hold_sticks(d, q, v, data, delta):
    """Keep the stuck bristles stuck across the load change whose free response is
    ``delta`` (module docstring): ``delta`` becomes the response with them as
    constraints, each one's sticking position in ``data`` moves by −μ/k; a bristle whose
    holding force would exceed its level is left free (the largest excess first)."""
    sticks, law, response, y = d.sticks, d.stick_law, d.stick_response, d.y
    minv = d.minv
    count, n = sticks.shape[0], minv.shape[0]
    stuck = np.zeros(count, np.bool_)
    force = np.zeros(count)
    for j in range(count):
        base, moving, mode, position = sticks[j, 0], sticks[j, 1], sticks[j, 2], sticks[j, 3]
        if data[mode] != 0.0:  # slipping
            continue
        stuck[j] = True
        force[j] = (law[j, 0] * (_relative(q, base, moving) - data[position])
                    + law[j, 1] * _relative(v, base, moving))
        for i in range(n):  # M⁻¹ Dⱼᵀ (M⁻¹ symmetric)
            y[i] = minv[moving, i] - (minv[base, i] if base >= 0 else 0.0)
        _project(d, y, response[j])
    while True:
        held = np.flatnonzero(stuck)
        k = held.shape[0]
        if k == 0:
            return
        A, rhs = np.empty((k, k)), np.empty(k)
        for r in range(k):
            base, moving = sticks[held[r], 0], sticks[held[r], 1]
            rhs[r] = _relative(delta, base, moving)
            for t in range(k):
                A[r, t] = _relative(response[held[t]], base, moving)
        mu = np.linalg.solve(A, rhs)
        worst, excess = -1, 1.0
        for r in range(k):
            ratio = abs(force[held[r]] + mu[r]) / law[held[r], 2]
            if ratio > excess:
                worst, excess = held[r], ratio
        if worst < 0:
            break
        stuck[worst] = False
    for r in range(k):
        j = held[r]
        for i in range(n):
            delta[i] -= mu[r] * response[j, i]
        data[sticks[j, 3]] -= mu[r] / law[j, 0]


@njit(cache=True)
def restart(d, q, v, a, data):
    """Move the step's start (q, q̇, q̈ and the bristles' sticking positions in ``data``;
    in place) as the loads changed by ``d.change`` demand: Δq̈ = W B(q) change, with the
    stuck bristles held (`hold_sticks`), then the shifts of `ExactHold` (module
    docstring)."""
    delta = d.delta
    response_into(d, q, delta)
    if d.sticks.shape[0] > 0:
        hold_sticks(d, q, v, data, delta)
    fq, fv, fa = d.factors[0], d.factors[1], d.factors[2]
    for i in range(q.shape[0]):
        q[i] += fq * delta[i]
        v[i] += fv * delta[i]
        a[i] += fa * delta[i]
