"""What happens at a control instant, defined once and compiled (numba).

`pre_sample`: the divergence bounds, the reference (eq. 37 or a quintic move), sensor
noise, the whole-sample delay, and the recording of truth, reference and measurement.
`post_sample`: the finite check of the torque, saturation, disturbances, and their
recording.  Between the two the laws run: as Python objects (any plug-in) or, for the
built-in laws, compiled (`laws`).  `run_reduced` is the whole loop for the reduced plant
with built-in laws: one compiled call per run.  The Python loop (`validation.loop`) calls
the same kernels once per sample, so every path computes the same sample.

Status codes returned: 0 ok; 1 state not finite; 2 |θ| beyond bounds; 3 |θ̇| beyond;
4, 5 tip deflection of link 1, 2 beyond; 6 measurement not finite; 7 torque not finite;
8 the observer's covariance update failed (the EKF).  ``info[0]`` holds the offending
value.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from controllers._baselines import rigid_torque
from controllers._ekf import _ekf_update
from controllers._lqr import _lqr_torque
from controllers._pbc import _pbc_torque
from controllers._smo import _smo_update
from reduced_model._kernels import rk4_advance_packed, tip_kinematics_packed

__all__ = ["pre_sample", "post_sample", "laws", "run_reduced", "check_bounds", "OFFSETS",
           "CONTROLLER_CODES", "OBSERVER_CODES"]

#: Order of the entries of the ``off`` array: where each signal group starts in a row.
OFFSETS = ("ref", "ref_rate", "tip_ref", "xhat", "y", "tau_cmd", "tau", "residual", "dist")
CONTROLLER_CODES = {"pbc": 0, "pbc-idealised": 1, "pd": 2, "ct": 3, "lqr": 4}
OBSERVER_CODES = {"none": -1, "smo-paper": 0, "smo-bl": 1, "smo-pos": 2, "ekf": 3, "ekf-pos": 3}


@njit(cache=True)
def _reference(kind, spec, t, out):
    """θ_d, θ̇_d, θ̈_d into out[0:2], out[2:4], out[4:6] (`controllers._reference`)."""
    if kind == 0:  # eq. (37)
        a1, a2, w1, w2 = spec[0], spec[1], spec[2], spec[3]
        s1, c1, s2, c2 = math.sin(w1 * t), math.cos(w1 * t), math.sin(w2 * t), math.cos(w2 * t)
        out[0], out[1] = a1 * s1, a2 * s2
        out[2], out[3] = a1 * w1 * c1, a2 * w2 * c2
        out[4], out[5] = -a1 * w1 * w1 * s1, -a2 * w2 * w2 * s2
        return
    T = spec[4]
    tau = min(max(t / T, 0.0), 1.0)
    s = tau ** 3 * (10 - 15 * tau + 6 * tau ** 2)
    ds = 30 * tau ** 2 * (1 - tau) ** 2 / T if 0 < t < T else 0.0
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / T ** 2 if 0 < t < T else 0.0
    for j in range(2):
        d = spec[7 + j] - spec[5 + j]
        out[j] = spec[5 + j] + s * d
        out[2 + j] = ds * d
        out[4 + j] = dds * d


@njit(cache=True)
def check_bounds(truth, n, bounds, info):
    """0, or why the state must stop the run: [max angle, max rate, max deflection of
    link 1, of link 2] in ``bounds``."""
    total = 0.0
    for i in range(truth.shape[0]):
        total += truth[i]
    if not math.isfinite(total):
        return 1
    angle = max(abs(truth[0]), abs(truth[1]))
    if angle > bounds[0]:
        info[0] = angle
        return 2
    rate = max(abs(truth[n]), abs(truth[n + 1]))
    if rate > bounds[1]:
        info[0] = rate
        return 3
    for i in range(2):
        w = truth[2 * n + 4 + i]
        if abs(w) > bounds[2 + i]:
            info[0] = w
            return 4 + i
    return 0


@njit(cache=True)
def pre_sample(t, truth, yv, std, noisy, dbuf, k, rng, refkind, refspec, bounds, n, lengths,
               row, off, y_used, ref, info):
    """Bounds, reference, noisy and delayed measurement, recording; the status code."""
    for i in range(truth.shape[0]):
        row[i] = truth[i]
    code = check_bounds(truth, n, bounds, info)
    if code != 0:
        return code
    _reference(refkind, refspec, t, ref)
    row[off[0]], row[off[0] + 1] = ref[0], ref[1]
    row[off[1]], row[off[1] + 1] = ref[2], ref[3]
    a1 = ref[0]
    a12 = a1 + ref[1]
    row[off[2]] = lengths[0] * math.cos(a1) + lengths[1] * math.cos(a12)
    row[off[2] + 1] = lengths[0] * math.sin(a1) + lengths[1] * math.sin(a12)
    depth = dbuf.shape[0]
    slot = k % depth
    total = 0.0
    for i in range(yv.shape[0]):
        v = yv[i] + std[i] * rng.standard_normal() if noisy else yv[i]
        dbuf[slot, i] = v
        total += v
    if not math.isfinite(total):
        return 6
    oldest = (k - min(k + 1, depth) + 1) % depth
    for i in range(yv.shape[0]):
        y_used[i] = dbuf[oldest, i]
        row[off[4] + i] = y_used[i]
    return 0


@njit(cache=True)
def post_sample(t, tau, n_tau, limit, dspec, dstate, rng, row, off, tau_plant, force):
    """Finite check, saturation, disturbances and recording of the law's torque ``tau``
    (its first ``n_tau`` entries); ``tau_plant`` receives what the plant gets (length
    ``n_tau``), ``force`` the payload force.  Returns the status code.  ``tau`` itself
    becomes the applied torque the observer sees next (saturated, no disturbance)."""
    total = 0.0
    for i in range(n_tau):
        total += tau[i]
    if not math.isfinite(total):
        return 7
    row[off[5]], row[off[5] + 1] = tau[0], tau[1]
    if limit > 0:
        for i in range(2):
            tau[i] = min(max(tau[i], -limit), limit)
    row[off[6]], row[off[6] + 1] = tau[0], tau[1]
    for i in range(n_tau):
        tau_plant[i] = tau[i]
    v0 = v1 = v2 = v3 = 0.0
    for i in range(dspec.shape[0]):
        kind, target = int(dspec[i, 0]), int(dspec[i, 1])
        amp, start, duration, freq, decay = (dspec[i, 2], dspec[i, 3], dspec[i, 4],
                                             dspec[i, 5], dspec[i, 6])
        if t < start - 1e-9:
            continue
        if kind == 0:  # step
            x = amp
        elif kind == 1:  # pulse
            x = amp if t < start + duration - 1e-9 else 0.0
        elif kind == 2:  # sine
            x = amp * np.sin(2 * np.pi * freq * (t - start))
        else:  # low-passed white noise of standard deviation amp
            dstate[i] = decay * dstate[i] + np.sqrt(1 - decay * decay) * amp * rng.standard_normal()
            x = dstate[i]
        if target == 0:
            v0 += x
        elif target == 1:
            v1 += x
        elif target == 2:
            v2 += x
        else:
            v3 += x
    row[off[8]], row[off[8] + 1], row[off[8] + 2], row[off[8] + 3] = v0, v1, v2, v3
    tau_plant[0] += v0
    tau_plant[1] += v1
    force[0], force[1] = v2, v3
    return 0


@njit(cache=True)
def laws(t, Ts, y_obs, obs_idx, last_tau, state, use_estimate, ref, row, off,
         ccode, cm_i, cm_r, c_wc, c_wr, ci, cf, cw,
         ocode, om_i, om_r, o_wc, o_wr, oi, of, ow, x_hat, tau):
    """The built-in observer (code ``ocode``, −1: none) then controller (``ccode``),
    on the state of their compiled form (`validation._compiled_laws`).  Writes the
    estimate into ``x_hat`` and row, the torque into ``tau``; returns (status, n_tau)."""
    N = state.shape[0]
    n = N // 2
    if ocode >= 0:
        for i in range(obs_idx.shape[0]):
            y_obs[i] = row[off[4] + obs_idx[i]]
        if ocode <= 2:  # sliding-mode observers
            x = ow[:N]
            _smo_update(om_i, om_r, o_wc, o_wr, x, last_tau, Ts, oi[1], oi[2] == 0, y_obs,
                        of[:n], of[n:2 * n], ocode, of[2 * n], of[2 * n + 1], of[2 * n + 2],
                        ow[N:N + n])
        else:  # extended Kalman filter
            m = oi[0]
            x = ow[:N]
            P = ow[N:N + N * N].reshape((N, N))
            b = N + N * N
            ok = _ekf_update(om_i, om_r, o_wc, o_wr, x, P, last_tau, Ts / oi[1], oi[1],
                             oi[2] == 0, y_obs, of[:m], of[m:m + N * N].reshape((N, N)),
                             ow[b:b + N], ow[b + N:b + 2 * N],
                             ow[b + 2 * N:b + 2 * N + N * N].reshape((N, N)),
                             ow[b + 2 * N + N * N:b + 2 * N + 2 * N * N].reshape((N, N)),
                             ow[b + 2 * N + 2 * N * N:b + 2 * N + 3 * N * N].reshape((N, N)),
                             ow[b + 2 * N + 3 * N * N:b + 2 * N + 3 * N * N + N * m].reshape((N, m)),
                             ow[b + 2 * N + 3 * N * N + N * m:b + 2 * N + 3 * N * N + N * m + m * m].reshape((m, m)),
                             ow[b + 2 * N + 3 * N * N + N * m + m * m:b + 2 * N + 3 * N * N + N * m + m * m + m])
            if not ok:
                for i in range(N):
                    x[i] = np.nan
        oi[2] = 0  # no longer fresh: later calls predict
        for i in range(N):
            x_hat[i] = x[i]
            row[off[3] + i] = x[i]
    xc = x_hat if use_estimate else state
    th, dth, ddth = ref[0:2], ref[2:4], ref[4:6]
    if ccode <= 1:  # PBC, eq. (20)
        lam, kv = cf[:n], cf[n:2 * n]
        M = cw[:n * n].reshape((n, n))
        C = cw[n * n:2 * n * n].reshape((n, n))
        scratch = cw[2 * n * n:2 * n * n + 4 * n]
        full = cw[2 * n * n + 4 * n:2 * n * n + 5 * n]
        _pbc_torque(cm_i, cm_r, c_wc, c_wr, M, C, scratch, xc, th, dth, ddth, lam, kv,
                    ci[0] == 1, full)
        if ccode == 1:
            for i in range(n):
                tau[i] = full[i]
            return 0, n
        for i in range(n - 2):
            row[off[7] + i] = full[2 + i]
        tau[0], tau[1] = full[0], full[1]
        return 0, 2
    if ccode == 2:  # joint PD (+ rigid feedforward)
        for i in range(2):
            tau[i] = cf[i] * (th[i] - xc[i]) + cf[2 + i] * (dth[i] - xc[n + i])
        if ci[0] == 1:
            ff = cw[:2]
            rigid_torque(cf[4:8], th, dth, ddth, ff)
            tau[0] = tau[0] + ff[0]
            tau[1] = tau[1] + ff[1]
        return 0, 2
    if ccode == 3:  # rigid computed torque
        accel = cw[:2]
        for i in range(2):
            accel[i] = ddth[i] + cf[2 + i] * (dth[i] - xc[n + i]) + cf[i] * (th[i] - xc[i])
        rigid_torque(cf[4:8], xc[0:2], xc[n:n + 2], accel, tau)
        return 0, 2
    # gain-scheduled LQR
    rows = ci[0]
    table = cf[5:5 + rows * 2 * N].reshape((rows, 2, N))
    _lqr_torque(table, cf[0], cf[1:5], cw[:2 * N].reshape((2, N)), xc, th, dth, ddth, tau)
    return 0, 2


@njit(cache=True)
def _reduced_truth(xp, basis, n, pm_i, pm_r, tips, truth):
    """The reduced plant's truth vector: [θ, q, θ̇, q̇] in the model's basis (``basis``
    maps the plant's modal coordinates; 0 × 0: the same), tips, tip deflections, 0, 0."""
    N = 2 * n
    npl = xp.shape[0] // 2
    if basis.shape[0] == 0:
        for i in range(N):
            truth[i] = xp[i]
    else:
        truth[0], truth[1] = xp[0], xp[1]
        truth[n], truth[n + 1] = xp[npl], xp[npl + 1]
        for i in range(n - 2):
            q = 0.0
            qd = 0.0
            for j in range(npl - 2):
                q += basis[i, j] * xp[2 + j]
                qd += basis[i, j] * xp[npl + 2 + j]
            truth[2 + i] = q
            truth[n + 2 + i] = qd
    tip_kinematics_packed(pm_i, pm_r, xp[:npl], tips)
    for i in range(6):
        truth[N + i] = tips[i]
    truth[N + 6] = truth[N + 7] = 0.0


@njit(cache=True)
def run_reduced(N_samples, Ts, h, nsteps, xp, pm_i, pm_r, p_wc, p_wr, basis, y_idx,
                std, noisy, dbuf, rng, refkind, refspec, bounds, n, lengths, rows, off,
                limit, dspec, dstate, rng2,
                ccode, cm_i, cm_r, c_wc, c_wr, ci, cf, cw,
                ocode, om_i, om_r, o_wc, o_wr, oi, of, ow, obs_idx, use_estimate, info):
    """The closed loop on the reduced plant, every sample compiled: returns (samples
    done, status code).  ``xp`` is the plant state (its own coordinates); ``basis`` maps
    its modal coordinates to the model's (0 × 0: the same basis)."""
    N = 2 * n
    truth = np.zeros(N + 8)
    tips = np.zeros(6)
    yv = np.zeros(y_idx.shape[0])
    y_used = np.zeros(y_idx.shape[0])
    y_obs = np.zeros(obs_idx.shape[0])
    ref = np.zeros(6)
    x_hat = np.zeros(N)
    tau = np.zeros(N)
    last_tau = np.zeros(N)
    tau_plant = np.zeros(N)
    force = np.zeros(2)
    n_last = 2
    for k in range(N_samples):
        t = k * Ts
        _reduced_truth(xp, basis, n, pm_i, pm_r, tips, truth)
        for i in range(y_idx.shape[0]):
            yv[i] = truth[y_idx[i]]
        row = rows[k]
        code = pre_sample(t, truth, yv, std, noisy, dbuf, k, rng, refkind, refspec, bounds,
                          n, lengths, row, off, y_used, ref, info)
        if code != 0:
            return k, code
        code, n_tau = laws(t, Ts, y_obs, obs_idx, last_tau[:n_last], truth[:N], use_estimate,
                           ref, row, off, ccode, cm_i, cm_r, c_wc, c_wr, ci, cf, cw,
                           ocode, om_i, om_r, o_wc, o_wr, oi, of, ow, x_hat, tau)
        code = post_sample(t, tau, n_tau, limit, dspec, dstate, rng2, row, off, tau_plant,
                           force)
        if code != 0:
            return k, code
        for i in range(n_tau):
            last_tau[i] = tau[i]
        n_last = n_tau
        rk4_advance_packed(pm_i, pm_r, p_wc, p_wr, xp, tau_plant[:n_tau], h, nsteps)
    # the state after the last period is checked too (as the Python loop does)
    _reduced_truth(xp, basis, n, pm_i, pm_r, tips, truth)
    return N_samples, check_bounds(truth, n, bounds, info)


# --- the built-in laws' compiled form -----------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _unused_model():
    """Model and workspace buffers of the right types for a law that has none (the
    compiled `laws` is typed for every branch)."""
    from reduced_model import ArmModel
    model = ArmModel()
    return (*model.packed, *model.new_workspace()[0])


def pack_laws(controller, observer, Ts: float):
    """The arguments of `laws` for a built-in controller and observer (their state
    copied as it is now), or None if either is a plug-in (the loop then calls the
    Python objects).  Exact classes only: a subclass may change the law."""
    from controllers import (BoundaryLayerSMO, ExtendedKalmanFilter, GainScheduledLQR,
                             IdealisedPBC, JointPD, PassivityBasedController, PaperSMO,
                             PositionEKF, PositionOnlySMO, RigidComputedTorque)
    from controllers._smo import _MAX_SUBSTEP
    c = controller
    kind = type(c)
    if kind in (PassivityBasedController, IdealisedPBC):
        n = c.model.n
        ctrl = (int(kind is IdealisedPBC), *c.model.packed, *c._work,
                np.array([int(c.compensate_damping)], dtype=np.int64),
                np.concatenate([c.lam, c.kv]), np.zeros(2 * n * n + 5 * n))
    elif kind in (JointPD, RigidComputedTorque):
        ff = c.rigid.constants if c.rigid is not None else np.zeros(4)
        ctrl = (2 if kind is JointPD else 3, *_unused_model(),
                np.array([int(c.rigid is not None)], dtype=np.int64),
                np.concatenate([c.kp, c.kd, ff]), np.zeros(2))
    elif kind is GainScheduledLQR:
        ctrl = (4, *_unused_model(),
                np.array([c._table.shape[0]], dtype=np.int64),
                np.concatenate([[c._scale], c._ff, c._table.ravel()]), np.zeros(c._K.size))
    else:
        return None
    o = observer
    kind = type(o)
    if o is None:
        obs = (-1, *_unused_model(), np.zeros(3, dtype=np.int64), np.zeros(1), np.zeros(1))
    elif kind in (PaperSMO, BoundaryLayerSMO, PositionOnlySMO):
        nsub = max(1, math.ceil(Ts / _MAX_SUBSTEP - 1e-9))
        obs = (o._variant, *o.model.packed, *o._work,
               np.array([0, nsub, int(o._fresh)], dtype=np.int64),
               np.concatenate([o.lp, o.lv, [o.boundary_layer, min(1.0, Ts / o.filter_time),
                                            o.gate]]),
               np.concatenate([o._x, o._nu]))
    elif kind in (ExtendedKalmanFilter, PositionEKF):
        o._set_period(Ts)
        N, m = o._x.shape[0], o._m
        scratch = 2 * N + 3 * N * N + N * m + m * m + m
        obs = (3, *o.model.packed, *o._work,
               np.array([m, o._nsub, int(o._fresh)], dtype=np.int64),
               np.concatenate([o._r, o._Qd.ravel()]),
               np.concatenate([o._x, o._P.ravel(), np.zeros(scratch)]))
    else:
        return None
    return ctrl + obs
