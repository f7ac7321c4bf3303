"""What happens at a control instant, defined once and compiled (numba).

`pre_sample`: the divergence bounds, the reference (eq. 37 or a quintic move), sensor
noise, the whole-sample delay, and the recording of truth, reference and measurement.
`post_sample`: the finite check of the torque, saturation, disturbances, and their
recording.  Between the two the laws run: as Python objects (any law without a compiled
form), or compiled, through the function pointers of their compiled forms
(`controllers._compiled`) in `sample_laws`.  `run_reduced` is the whole loop on the
reduced plant with compiled laws: one compiled call per run.  The Python loop
(`validation.run.loop`) calls the same kernels once per sample, so every path computes
the same sample.

The kernels that take function pointers are compiled for one explicit signature
(`compile_sample_laws`, `compile_run_reduced`) the first time a run needs them, so they
are compiled — and cached — once, whatever the laws.  Noise is drawn in advance from the
run's seeded generators, in the order the samples consume it (`noise_stream`): a
generator passed to compiled code costs ~10 µs per call, a stream costs nothing.

The codes the kernels return and the layout of the rows they record are defined here,
with their meanings: `SampleStatus`, `DisturbanceKind`, `DisturbanceTarget`, `Group`.
"""
from __future__ import annotations

import functools
import math
from enum import IntEnum

import numpy as np
from numba import njit, types

from controllers import CONTROLLER_SIGNATURE, OBSERVER_SIGNATURE, reference_into
from reduced_model._kernels import rk4_advance_packed, tip_kinematics_packed

__all__ = ["SampleStatus", "status_message", "DisturbanceKind", "DisturbanceTarget", "Group",
           "signal_layout", "noise_stream", "pre_sample", "post_sample", "check_bounds",
           "sample_laws", "run_reduced", "compile_sample_laws", "compile_run_reduced"]


class SampleStatus(IntEnum):
    """Why a sample ends the run (0: it does not); see `status_message`."""

    OK = 0
    STATE_NOT_FINITE = 1
    ANGLE = 2
    RATE = 3
    DEFLECTION_1 = 4
    DEFLECTION_2 = 5
    MEASUREMENT_NOT_FINITE = 6
    TORQUE_NOT_FINITE = 7
    OBSERVER_FAILED = 8


def status_message(code: int, value: float, divergence, t: float, observer: str = "") -> str:
    """The message of a `SampleStatus` (``value``: the offending value the kernel left in
    ``info[0]``; ``divergence``: the scenario's `DivergenceSpec`; ``observer``: what the
    observer's failure means, "name: reason")."""
    code = SampleStatus(code)
    if code is SampleStatus.OK:
        return ""
    d = divergence
    text = {
        SampleStatus.STATE_NOT_FINITE: "state not finite",
        SampleStatus.ANGLE: f"|θ| = {value:.3g} rad exceeds {d.max_angle:g} rad",
        SampleStatus.RATE: f"|θ̇| = {value:.3g} rad/s exceeds {d.max_rate:g} rad/s",
        SampleStatus.DEFLECTION_1: f"tip deflection of link 1 = {value:.3g} m exceeds "
                                   f"{d.max_deflection:g} x its length",
        SampleStatus.DEFLECTION_2: f"tip deflection of link 2 = {value:.3g} m exceeds "
                                   f"{d.max_deflection:g} x its length",
        SampleStatus.MEASUREMENT_NOT_FINITE: "measurement not finite",
        SampleStatus.TORQUE_NOT_FINITE: "controller output not finite",
        SampleStatus.OBSERVER_FAILED: observer or "the observer failed",
    }[code]
    return f"{text} at t = {t:.4g} s"


class DisturbanceKind(IntEnum):
    """Disturbance signals (`post_sample`): "step" from ``start``; "pulse" during
    [start, start + duration); "sine" amplitude·sin(2π·frequency·(t − start));
    "noise": Gaussian of standard deviation ``amplitude`` low-passed at ``bandwidth``."""

    STEP = 0
    PULSE = 1
    SINE = 2
    NOISE = 3


class DisturbanceTarget(IntEnum):
    """Where a disturbance acts: a joint torque [N m] or the payload [N, base frame]."""

    TAU1 = 0
    TAU2 = 1
    TIP_X = 2
    TIP_Y = 3


class Group(IntEnum):
    """The groups of signals in a recorded row, in their order (`signal_layout`)."""

    TRUTH = 0  # the state [θ, q, θ̇, q̇] in the model's coordinates
    TIPS = 1  # reduced_model's TRUTH_EXTRAS: tips, tip deflections, projection residuals
    REF = 2
    REF_RATE = 3
    TIP_REF = 4
    XHAT = 5
    Y = 6
    TAU_CMD = 7
    TAU = 8
    RESIDUAL = 9
    DIST = 10


def signal_layout(state_names, truth_extras, measured, has_observer: bool,
                  residual_names) -> tuple[tuple[str, ...], np.ndarray]:
    """The names of a row's signals and where each `Group` starts (offsets indexed by
    `Group`; the kernels write there)."""
    groups = {
        Group.TRUTH: tuple(state_names),
        Group.TIPS: tuple(truth_extras),
        Group.REF: ("theta1_ref", "theta2_ref"),
        Group.REF_RATE: ("theta1_dot_ref", "theta2_dot_ref"),
        Group.TIP_REF: ("tip_ref_x", "tip_ref_y"),
        Group.XHAT: tuple(f"xhat_{s}" for s in state_names) if has_observer else (),
        Group.Y: tuple(f"y_{m}" for m in measured),
        Group.TAU_CMD: ("tau1_cmd", "tau2_cmd"),
        Group.TAU: ("tau1", "tau2"),
        Group.RESIDUAL: tuple(f"residual_{r}" for r in residual_names),
        Group.DIST: ("dist_tau1", "dist_tau2", "dist_tip_x", "dist_tip_y"),
    }
    names, offsets = [], np.zeros(len(Group), dtype=np.int64)
    for group in Group:
        offsets[group] = len(names)
        names += groups[group]
    return tuple(names), offsets


def noise_stream(rng: np.random.Generator, shape) -> np.ndarray:
    """Standard normal draws for the kernels, in the order they consume them (identical
    to drawing one at a time: numba's generator and NumPy's give the same stream)."""
    return np.ascontiguousarray(rng.standard_normal(shape))


@njit(cache=True)
def check_bounds(truth, n, bounds, info):
    """`SampleStatus` of the state: [max angle, max rate, max deflection of link 1, of
    link 2] in ``bounds``; the offending value into ``info[0]``."""
    total = 0.0
    for i in range(truth.shape[0]):
        total += truth[i]
    if not math.isfinite(total):
        return SampleStatus.STATE_NOT_FINITE
    angle = max(abs(truth[0]), abs(truth[1]))
    if angle > bounds[0]:
        info[0] = angle
        return SampleStatus.ANGLE
    rate = max(abs(truth[n]), abs(truth[n + 1]))
    if rate > bounds[1]:
        info[0] = rate
        return SampleStatus.RATE
    for i in range(2):
        w = truth[2 * n + 4 + i]
        if abs(w) > bounds[2 + i]:
            info[0] = w
            return SampleStatus.DEFLECTION_1 + i
    return SampleStatus.OK


@njit(cache=True)
def pre_sample(t, k, truth, yv, std, noise, dbuf, refkind, refspec, bounds, n, lengths,
               row, off, y_used, ref, info):
    """Bounds, reference, noisy and delayed measurement, recording; the `SampleStatus`
    (the offending value into ``info[0]``).  ``noise`` holds the standard normal draws
    of every sample (row k), or no rows when the sensors are exact."""
    for i in range(truth.shape[0]):
        row[i] = truth[i]
    code = check_bounds(truth, n, bounds, info)
    if code != SampleStatus.OK:
        return code
    reference_into(refkind, refspec, t, ref)
    row[off[Group.REF]], row[off[Group.REF] + 1] = ref[0], ref[1]
    row[off[Group.REF_RATE]], row[off[Group.REF_RATE] + 1] = ref[2], ref[3]
    a1 = ref[0]
    a12 = a1 + ref[1]
    row[off[Group.TIP_REF]] = lengths[0] * math.cos(a1) + lengths[1] * math.cos(a12)
    row[off[Group.TIP_REF] + 1] = lengths[0] * math.sin(a1) + lengths[1] * math.sin(a12)
    depth = dbuf.shape[0]
    slot = k % depth
    noisy = noise.shape[0] > 0
    total = 0.0
    for i in range(yv.shape[0]):
        v = yv[i] + std[i] * noise[k, i] if noisy else yv[i]
        dbuf[slot, i] = v
        total += v
    if not math.isfinite(total):
        return SampleStatus.MEASUREMENT_NOT_FINITE
    oldest = (k - min(k + 1, depth) + 1) % depth
    for i in range(yv.shape[0]):
        y_used[i] = dbuf[oldest, i]
        row[off[Group.Y] + i] = y_used[i]
    return SampleStatus.OK


@njit(cache=True)
def post_sample(t, tau, n_tau, limit, dspec, dstate, dnoise, counts, row, off, tau_plant,
                force):
    """Finite check, saturation, disturbances and recording of the law's torque ``tau``
    (its first ``n_tau`` entries); ``tau_plant`` receives what the plant gets (length
    ``n_tau``), ``force`` the payload force.  Returns the `SampleStatus`.  ``tau``
    itself becomes the applied torque the observer sees next (saturated, no
    disturbance).  Noise disturbances take their draws from ``dnoise`` from
    ``counts[0]`` on; ``counts[1]`` becomes ``n_tau`` (what the observer is told next)."""
    total = 0.0
    for i in range(n_tau):
        total += tau[i]
    if not math.isfinite(total):
        return SampleStatus.TORQUE_NOT_FINITE
    row[off[Group.TAU_CMD]], row[off[Group.TAU_CMD] + 1] = tau[0], tau[1]
    if limit > 0:
        for i in range(2):
            tau[i] = min(max(tau[i], -limit), limit)
    row[off[Group.TAU]], row[off[Group.TAU] + 1] = tau[0], tau[1]
    for i in range(n_tau):
        tau_plant[i] = tau[i]
    acting = row[off[Group.DIST]:off[Group.DIST] + 4]  # indexed by DisturbanceTarget
    acting[:] = 0.0
    for i in range(dspec.shape[0]):
        kind, target = int(dspec[i, 0]), int(dspec[i, 1])
        amp, start, duration, freq, decay = (dspec[i, 2], dspec[i, 3], dspec[i, 4],
                                             dspec[i, 5], dspec[i, 6])
        if t < start - 1e-9:
            continue
        if kind == DisturbanceKind.STEP:
            x = amp
        elif kind == DisturbanceKind.PULSE:
            x = amp if t < start + duration - 1e-9 else 0.0
        elif kind == DisturbanceKind.SINE:
            x = amp * np.sin(2 * np.pi * freq * (t - start))
        else:  # DisturbanceKind.NOISE
            dstate[i] = (decay * dstate[i]
                         + np.sqrt(1 - decay * decay) * amp * dnoise[counts[0]])
            counts[0] += 1
            x = dstate[i]
        acting[target] += x
    tau_plant[0] += acting[DisturbanceTarget.TAU1]
    tau_plant[1] += acting[DisturbanceTarget.TAU2]
    force[0], force[1] = acting[DisturbanceTarget.TIP_X], acting[DisturbanceTarget.TIP_Y]
    counts[1] = n_tau
    return SampleStatus.OK


@njit(cache=True)
def sample_laws(t, k, Ts, truth, yv, std, noise, dbuf, refkind, refspec, bounds, n,
                lengths, row, off, y_used, ref, info, limit, dspec, dstate, dnoise, counts,
                last_tau, x_hat, y_obs, obs_idx, has_observer, use_estimate, tau, tau_plant,
                force, controller, c_ints, c_reals, c_state, c_mi, c_mr, c_wc, c_wr,
                observer, o_ints, o_reals, o_state, o_mi, o_mr, o_wc, o_wr):
    """One whole sample with compiled laws: `pre_sample`, the observer and the
    controller through their function pointers, `post_sample`.  Returns the
    `SampleStatus`; the torques are then in ``tau``/``tau_plant`` (``counts[1]`` of
    them) and in ``last_tau`` (the observer's input at the next sample)."""
    code = pre_sample(t, k, truth, yv, std, noise, dbuf, refkind, refspec, bounds, n,
                      lengths, row, off, y_used, ref, info)
    if code != SampleStatus.OK:
        return code
    N = 2 * n
    if has_observer:
        for i in range(obs_idx.shape[0]):
            y_obs[i] = y_used[obs_idx[i]]
        failed = observer(t, Ts, y_obs, last_tau[:counts[1]], o_ints, o_reals, o_state, o_mi,
                          o_mr, o_wc, o_wr, x_hat)
        for i in range(N):
            row[off[Group.XHAT] + i] = x_hat[i]
        if failed != 0:
            return SampleStatus.OBSERVER_FAILED
    fed = x_hat if use_estimate else truth[:N]
    residual = row[off[Group.RESIDUAL]:off[Group.DIST]]
    n_tau = controller(t, fed, ref, c_ints, c_reals, c_state, c_mi, c_mr, c_wc, c_wr, tau,
                       residual)
    code = post_sample(t, tau, n_tau, limit, dspec, dstate, dnoise, counts, row, off,
                       tau_plant, force)
    if code != SampleStatus.OK:
        return code
    for i in range(n_tau):
        last_tau[i] = tau[i]
    return SampleStatus.OK


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
def run_reduced(n_samples, Ts, h, nsteps, xp, pm_i, pm_r, p_wc, p_wr, basis, y_idx,
                std, noise, dbuf, refkind, refspec, bounds, n, lengths, rows, off, info,
                limit, dspec, dstate, dnoise, obs_idx, has_observer, use_estimate,
                controller, c_ints, c_reals, c_state, c_mi, c_mr, c_wc, c_wr,
                observer, o_ints, o_reals, o_state, o_mi, o_mr, o_wc, o_wr):
    """The closed loop on the reduced plant, every sample compiled (`sample_laws`):
    returns the samples done and the `SampleStatus` (the offending value in
    ``info[0]``).  ``xp`` is the plant state (its own coordinates); ``basis`` maps its
    modal coordinates to the model's (0 × 0: the same basis)."""
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
    counts = np.array([0, 2], dtype=np.int64)
    for k in range(n_samples):
        t = k * Ts
        _reduced_truth(xp, basis, n, pm_i, pm_r, tips, truth)
        for i in range(y_idx.shape[0]):
            yv[i] = truth[y_idx[i]]
        code = sample_laws(t, k, Ts, truth, yv, std, noise, dbuf, refkind, refspec, bounds,
                           n, lengths, rows[k], off, y_used, ref, info, limit, dspec, dstate,
                           dnoise, counts, last_tau, x_hat, y_obs, obs_idx, has_observer,
                           use_estimate, tau, tau_plant, force,
                           controller, c_ints, c_reals, c_state, c_mi, c_mr, c_wc, c_wr,
                           observer, o_ints, o_reals, o_state, o_mi, o_mr, o_wc, o_wr)
        if code != SampleStatus.OK:
            return k, code
        rk4_advance_packed(pm_i, pm_r, p_wc, p_wr, xp, tau_plant[:counts[1]], h, nsteps)
    # the state after the last period is checked too (as the Python loop does)
    _reduced_truth(xp, basis, n, pm_i, pm_r, tips, truth)
    return n_samples, check_bounds(truth, n, bounds, info)


# --- explicit signatures: compiled once for every law ------------------------------------------
_f8, _i8, _b1, _c16 = types.float64, types.int64, types.boolean, types.complex128
_V, _I, _C = types.Array(_f8, 1, "C"), types.Array(_i8, 1, "C"), types.Array(_c16, 1, "C")
_M, _MI = types.Array(_f8, 2, "C"), types.Array(_i8, 2, "C")
_CONTROLLER, _OBSERVER = types.FunctionType(CONTROLLER_SIGNATURE), types.FunctionType(OBSERVER_SIGNATURE)
_LAWS = (_CONTROLLER, _I, _V, _V, _I, _V, _C, _V, _OBSERVER, _I, _V, _V, _I, _V, _C, _V)


@functools.cache
def compile_sample_laws():
    """`sample_laws` compiled for its one signature (first use; then numba's cache)."""
    sig = _i8(_f8, _i8, _f8, _V, _V, _V, _M, _M, _i8, _V, _V, _i8, _V, _V, _I, _V, _V, _V,
              _f8, _M, _V, _V, _I, _V, _V, _V, _I, _b1, _b1, _V, _V, _V, *_LAWS)
    sample_laws.compile(sig.args)
    sample_laws.disable_compile()  # a call with other types is an error, not a new compile
    return sample_laws


@functools.cache
def compile_run_reduced():
    """`run_reduced` compiled for its one signature (first use; then numba's cache)."""
    sig = types.Tuple((_i8, _i8))(
        _i8, _f8, _f8, _i8, _V, _I, _V, _C, _V, _M, _I, _V, _M, _M, _i8, _V, _V, _i8, _V,
        _M, _I, _V, _f8, _M, _V, _V, _I, _b1, _b1, *_LAWS)
    compile_sample_laws()  # what run_reduced calls
    run_reduced.compile(sig.args)
    run_reduced.disable_compile()
    return run_reduced
