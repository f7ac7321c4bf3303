"""What happens at a control instant, defined once and compiled (numba).

`pre_sample`: the divergence bounds, the reference (eq. 37 or a quintic move), sensor
noise, the whole-sample delay, and the recording of truth, reference and measurement.
`post_sample`: the finite check of the torque, saturation, disturbances, and their
recording.  Between the two the laws run: as Python objects (any law without a compiled
form), or compiled, through the function pointers of their compiled forms
(`controllers._compiled`) in `sample_laws`.  `run_compiled` is the whole loop on a plant
with a compiled form (`reduced_model.CompiledPlant`, called through its pointer as the
laws are) with compiled laws: one compiled call per run.  The Python loop
(`validation.run.loop`) calls the same kernels once per sample, so every path computes
the same sample.  Every buffer is sized by the arm (N joints, n coordinates).

Every buffer of a run's samples — the scenario's constants, the noise, the laws' function
pointers and buffers, the scratch space — is allocated once and held by one
`SampleContext` (a numba structure passed by reference): a kernel call from Python costs
~1 µs whatever the run, where the same buffers as separate arguments cost ~20 µs (~0.12
µs per array, ~3.5 µs per function pointer).  Its type is the same for every law, so the
kernels compile — and are cached — once.  Noise is drawn in advance from the run's
seeded generators, in the order the samples consume it (`noise_stream`): a generator
passed to compiled code costs ~10 µs per call, a stream costs nothing.

The codes the kernels return and the layout of the rows they record are defined here,
with their meanings: `SampleStatus`, `DisturbanceKind`, `disturbance_target`, `Group`.
"""
from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit, types
from numba.experimental import structref

from controllers import CONTROLLER_SIGNATURE, OBSERVER_SIGNATURE, reference_into
from reduced_model.contract import PLANT_SIGNATURE, CompiledPlant, kernel_pointer

__all__ = ["SampleStatus", "status_message", "DisturbanceKind", "DISTURBANCE_TARGETS",
           "disturbance_target", "Group", "signal_layout", "noise_stream", "SampleContext",
           "new_context", "context", "law_fields", "plant_fields", "pre_sample",
           "post_sample", "check_bounds", "sample_laws", "run_compiled"]


class SampleStatus(IntEnum):
    """Why a sample ends the run (0: it does not); see `status_message`."""

    OK = 0
    STATE_NOT_FINITE = 1
    ANGLE = 2
    RATE = 3
    DEFLECTION = 4
    MEASUREMENT_NOT_FINITE = 5
    TORQUE_NOT_FINITE = 6
    OBSERVER_FAILED = 7


def status_message(code: int, info, divergence, t: float, observer: str = "") -> str:
    """The message of a `SampleStatus` (``info``: the kernel's ``info`` buffer, the
    offending value and, for a deflection, its link from 1; ``divergence``: the
    scenario's `DivergenceSpec`; ``observer``: what the observer's failure means,
    "name: reason")."""
    code = SampleStatus(code)
    if code is SampleStatus.OK:
        return ""
    d = divergence
    value = info[0]
    text = {
        SampleStatus.STATE_NOT_FINITE: "state not finite",
        SampleStatus.ANGLE: f"|θ| = {value:.3g} rad exceeds {d.max_angle:g} rad",
        SampleStatus.RATE: f"|θ̇| = {value:.3g} rad/s exceeds {d.max_rate:g} rad/s",
        SampleStatus.DEFLECTION: f"tip deflection of link {int(info[1])} = {value:.3g} m "
                                 f"exceeds {d.max_deflection:g} x its length",
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


#: Where a disturbance may act: a joint's torque [N m] or the payload [N, base frame].
DISTURBANCE_TARGETS = ("tau1", "tau2", "tau3", "tau4", "tip_x", "tip_y")


def disturbance_target(target: str, joints: int) -> int:
    """The code of ``target`` (`DISTURBANCE_TARGETS`) on an arm of ``joints`` joints:
    joint i's torque is i − 1, the payload's x and y are ``joints`` and ``joints`` + 1
    (`post_sample` adds the disturbances there)."""
    if target.startswith("tau"):
        return int(target[3:]) - 1
    return joints + (target == "tip_y")


class Group(IntEnum):
    """The groups of signals in a recorded row, in their order (`signal_layout`)."""

    # Each member's `#:` comment is its meaning in the signal-name reference of the docs.
    TRUTH = 0  #: The true state [θ, q, θ̇, q̇] in the laws' model coordinates [rad, m, rad/s, m/s].
    TIPS = 1  #: Tip positions in the base frame, tip deflections, modal projection residuals [m].
    REF = 2  #: The reference angles θ_d [rad].
    REF_RATE = 3  #: The reference rates θ̇_d [rad/s].
    TIP_REF = 4  #: The rigid arm's tip at θ_d [m].
    XHAT = 5  #: The observer's estimate of each state (only with an observer) [the state's unit].
    Y = 6  #: What the sensors read, noise and quantisation included [the reading's unit].
    TAU_CMD = 7  #: The controller's torque command [N m].
    TAU = 8  #: The torque the motors apply: the command saturated at the torque limit [N m].
    RESIDUAL = 9  #: The PBC's unrealisable flexible-coordinate forces (eq. 20, rows 2…) [N].
    DIST = 10  #: The disturbances on the joints [N m] and on the payload [N].


def signal_layout(state_names, truth_extras, measured, has_observer: bool,
                  residual_names, joints: int) -> tuple[tuple[str, ...], np.ndarray]:
    """The names of a row's signals and where each `Group` starts (offsets indexed by
    `Group`; the kernels write there), for an arm of ``joints`` joints."""
    ks = range(1, joints + 1)
    groups = {
        Group.TRUTH: tuple(state_names),
        Group.TIPS: tuple(truth_extras),
        Group.REF: tuple(f"theta{k}_ref" for k in ks),
        Group.REF_RATE: tuple(f"theta{k}_dot_ref" for k in ks),
        Group.TIP_REF: ("tip_ref_x", "tip_ref_y"),
        Group.XHAT: tuple(f"xhat_{s}" for s in state_names) if has_observer else (),
        Group.Y: tuple(f"y_{m}" for m in measured),
        Group.TAU_CMD: tuple(f"tau{k}_cmd" for k in ks),
        Group.TAU: tuple(f"tau{k}" for k in ks),
        Group.RESIDUAL: tuple(f"residual_{r}" for r in residual_names),
        Group.DIST: tuple(f"dist_tau{k}" for k in ks) + ("dist_tip_x", "dist_tip_y"),
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


# --- the context of a run's samples ------------------------------------------------------------
_f8, _i8, _b1, _c16 = types.float64, types.int64, types.boolean, types.complex128
_V, _I = types.Array(_f8, 1, "C"), types.Array(_i8, 1, "C")
_C, _M = types.Array(_c16, 1, "C"), types.Array(_f8, 2, "C")
_LAW = (_I, _V, _V, _I, _V, _C, _V)  # a compiled law's buffers (`controllers._compiled`)

#: What a `SampleContext` holds, in the order `new_context` takes it.
CONTEXT_FIELDS = (
    ("n", _i8),  # coordinates of the model: the state [θ, q, θ̇, q̇] has 2n
    ("joints", _i8),  # N: joints (and links)
    ("Ts", _f8),  # the control period [s]
    ("refkind", _i8), ("refspec", _V),  # the reference (`controllers.reference_into`)
    ("bounds", _V),  # divergence: max |θ|, max |θ̇|, max tip deflection of each link
    ("lengths", _V),  # each link's length (the reference's tip)
    ("info", _V),  # info[0]: the value that ended the run, info[1]: its link
    ("truth", _V),  # the plant's truth vector [x, tips...] at this sample
    ("y_idx", _I),  # where the measurement sits in the truth (empty: the plant gives yv)
    ("yv", _V), ("std", _V), ("noise", _M),  # measurement, noise std, draws per sample
    ("dbuf", _M), ("y_used", _V),  # the delay line and the (delayed, noisy) measurement
    ("ref", _V),  # θ_d, θ̇_d, θ̈_d at this sample
    ("off", _I),  # where each `Group` starts in a row
    ("limit", _f8),  # torque saturation [N m] (0: none)
    ("dspec", _M), ("dstate", _V), ("dnoise", _V),  # disturbances, their state and draws
    ("counts", _I),  # [noise draws used, torques applied at the last sample]
    ("has_observer", _b1), ("use_estimate", _b1),
    ("obs_idx", _I), ("y_obs", _V), ("x_hat", _V),  # what the observer reads, its estimate
    ("tau", _V), ("tau_plant", _V), ("force", _V), ("last_tau", _V),
    ("controller", types.FunctionType(CONTROLLER_SIGNATURE)),
    ("c_ints", _I), ("c_reals", _V), ("c_state", _V), ("c_mi", _I), ("c_mr", _V),
    ("c_wc", _C), ("c_wr", _V),
    ("observer", types.FunctionType(OBSERVER_SIGNATURE)),
    ("o_ints", _I), ("o_reals", _V), ("o_state", _V), ("o_mi", _I), ("o_mr", _V),
    ("o_wc", _C), ("o_wr", _V),
    ("plant", types.FunctionType(PLANT_SIGNATURE)),  # a compiled plant (`run_compiled`)
    ("p_ints", _I), ("p_reals", _V), ("p_state", _V), ("p_mi", _I), ("p_mr", _V),
    ("p_wc", _C), ("p_wr", _V), ("p_ext", _V),
)


@structref.register
class _ContextType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class SampleContext(structref.StructRefProxy):
    """The buffers of one run's samples (`CONTEXT_FIELDS`), made by `new_context`.  The
    Python side keeps its own references to the same arrays."""


structref.define_boxing(_ContextType, SampleContext)
_CONTEXT = _ContextType(CONTEXT_FIELDS)


def context(**fields) -> SampleContext:
    """A `SampleContext` from its fields by name: every name of `CONTEXT_FIELDS` once, no
    other (TypeError naming the difference); the compiled constructor takes them in that
    order."""
    names = [name for name, _ in CONTEXT_FIELDS]
    missing, unknown = set(names) - set(fields), set(fields) - set(names)
    if missing or unknown:
        raise TypeError(f"sample context: missing {sorted(missing)}, unknown {sorted(unknown)}")
    return new_context(*(fields[name] for name in names))


def law_fields(prefix: str, role: str, law) -> dict:
    """The context fields of a compiled law (`controllers.CompiledLaw`) or plant
    (`reduced_model.CompiledPlant`) by name: ``role`` (its kernel) and
    ``{prefix}_ints`` … ``{prefix}_wr``."""
    return {role: law.pointer, f"{prefix}_ints": law.ints, f"{prefix}_reals": law.reals,
            f"{prefix}_state": law.state, f"{prefix}_mi": law.model_ints,
            f"{prefix}_mr": law.model_reals, f"{prefix}_wc": law.work_complex,
            f"{prefix}_wr": law.work_real}


def plant_fields(form, coordinates: int) -> dict:
    """The context fields of a compiled plant (`reduced_model.CompiledPlant`; None: the
    plant is stepped from Python, and a kernel that does nothing holds its place), with
    the (zero) generalised forces of its ``coordinates`` a compiled loop holds."""
    if form is None:
        ints, reals = np.zeros(0, np.int64), np.zeros(0)
        form = CompiledPlant(kernel_pointer(_no_plant, PLANT_SIGNATURE), ints, reals, reals,
                             ints, reals, np.zeros(0, np.complex128), reals)
    return {**law_fields("p", "plant", form), "p_ext": np.zeros(coordinates)}


@njit(cache=True)
def _no_plant(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth):
    pass


@njit(cache=True)
def new_context(n, joints, Ts, refkind, refspec, bounds, lengths, info, truth, y_idx, yv, std,
                noise, dbuf, y_used, ref, off, limit, dspec, dstate, dnoise, counts,
                has_observer, use_estimate, obs_idx, y_obs, x_hat, tau, tau_plant, force,
                last_tau, controller, c_ints, c_reals, c_state, c_mi, c_mr, c_wc, c_wr,
                observer, o_ints, o_reals, o_state, o_mi, o_mr, o_wc, o_wr,
                plant, p_ints, p_reals, p_state, p_mi, p_mr, p_wc, p_wr, p_ext):
    """A `SampleContext` of these buffers (the arrays are shared, not copied)."""
    c = structref.new(_CONTEXT)
    c.n, c.joints, c.Ts, c.refkind, c.refspec = n, joints, Ts, refkind, refspec
    c.bounds, c.lengths = bounds, lengths
    c.info, c.truth, c.y_idx, c.yv, c.std, c.noise = info, truth, y_idx, yv, std, noise
    c.dbuf, c.y_used, c.ref, c.off, c.limit = dbuf, y_used, ref, off, limit
    c.dspec, c.dstate, c.dnoise, c.counts = dspec, dstate, dnoise, counts
    c.has_observer, c.use_estimate, c.obs_idx = has_observer, use_estimate, obs_idx
    c.y_obs, c.x_hat, c.tau, c.tau_plant, c.force = y_obs, x_hat, tau, tau_plant, force
    c.last_tau = last_tau
    c.controller, c.c_ints, c.c_reals, c.c_state = controller, c_ints, c_reals, c_state
    c.c_mi, c.c_mr, c.c_wc, c.c_wr = c_mi, c_mr, c_wc, c_wr
    c.observer, c.o_ints, c.o_reals, c.o_state = observer, o_ints, o_reals, o_state
    c.o_mi, c.o_mr, c.o_wc, c.o_wr = o_mi, o_mr, o_wc, o_wr
    c.plant, c.p_ints, c.p_reals, c.p_state = plant, p_ints, p_reals, p_state
    c.p_mi, c.p_mr, c.p_wc, c.p_wr, c.p_ext = p_mi, p_mr, p_wc, p_wr, p_ext
    return c


# --- the kernels -------------------------------------------------------------------------------
@njit(cache=True)
def check_bounds(truth, n, joints, bounds, info):
    """`SampleStatus` of the state: [max angle, max rate, max deflection of each link] in
    ``bounds``; the offending value into ``info[0]`` (a deflection's link into
    ``info[1]``)."""
    total = 0.0
    for i in range(truth.shape[0]):
        total += truth[i]
    if not math.isfinite(total):
        return SampleStatus.STATE_NOT_FINITE
    angle = 0.0
    rate = 0.0
    for i in range(joints):
        angle = max(angle, abs(truth[i]))
        rate = max(rate, abs(truth[n + i]))
    if angle > bounds[0]:
        info[0] = angle
        return SampleStatus.ANGLE
    if rate > bounds[1]:
        info[0] = rate
        return SampleStatus.RATE
    for i in range(joints):
        w = truth[2 * n + 2 * joints + i]
        if abs(w) > bounds[2 + i]:
            info[0] = w
            info[1] = i + 1
            return SampleStatus.DEFLECTION
    return SampleStatus.OK


@njit(cache=True)
def pre_sample(c, t, k, row):
    """Bounds, reference, noisy and delayed measurement, recording into ``row``; the
    `SampleStatus` (the offending value into ``c.info[0]``).  The truth is ``c.truth``;
    the measurement is read from it (``c.y_idx``) or was written to ``c.yv``."""
    truth, yv, off = c.truth, c.yv, c.off
    for i in range(truth.shape[0]):
        row[i] = truth[i]
    code = check_bounds(truth, c.n, c.joints, c.bounds, c.info)
    if code != SampleStatus.OK:
        return code
    ref = c.ref
    N = c.joints
    reference_into(c.refkind, c.refspec, t, ref)
    x = 0.0
    y = 0.0
    a = 0.0
    for i in range(N):
        row[off[Group.REF] + i] = ref[i]
        row[off[Group.REF_RATE] + i] = ref[N + i]
        a = a + ref[i]
        x = x + c.lengths[i] * math.cos(a)
        y = y + c.lengths[i] * math.sin(a)
    row[off[Group.TIP_REF]] = x
    row[off[Group.TIP_REF] + 1] = y
    for i in range(c.y_idx.shape[0]):
        yv[i] = truth[c.y_idx[i]]
    dbuf, noise, std = c.dbuf, c.noise, c.std
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
        c.y_used[i] = dbuf[oldest, i]
        row[off[Group.Y] + i] = c.y_used[i]
    return SampleStatus.OK


@njit(cache=True)
def post_sample(c, t, n_tau, row):
    """Finite check, saturation, disturbances and recording of the law's torque ``c.tau``
    (its first ``n_tau`` entries); ``c.tau_plant`` receives what the plant gets (length
    ``n_tau``), ``c.force`` the payload force.  Returns the `SampleStatus`.  ``c.tau``
    itself becomes the applied torque the observer sees next (saturated, no
    disturbance): it is kept in ``c.last_tau``, ``n_tau`` in ``c.counts[1]``.  Noise
    disturbances take their draws from ``c.dnoise`` from ``c.counts[0]`` on."""
    tau, off, tau_plant, dspec = c.tau, c.off, c.tau_plant, c.dspec
    N = c.joints
    total = 0.0
    for i in range(n_tau):
        total += tau[i]
    if not math.isfinite(total):
        return SampleStatus.TORQUE_NOT_FINITE
    for i in range(N):
        row[off[Group.TAU_CMD] + i] = tau[i]
    if c.limit > 0:
        for i in range(N):
            tau[i] = min(max(tau[i], -c.limit), c.limit)
    for i in range(N):
        row[off[Group.TAU] + i] = tau[i]
    for i in range(n_tau):
        tau_plant[i] = tau[i]
        c.last_tau[i] = tau[i]
    c.counts[1] = n_tau
    acting = row[off[Group.DIST]:off[Group.DIST] + N + 2]  # by `disturbance_target`
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
            c.dstate[i] = (decay * c.dstate[i]
                           + np.sqrt(1 - decay * decay) * amp * c.dnoise[c.counts[0]])
            c.counts[0] += 1
            x = c.dstate[i]
        acting[target] += x
    for i in range(N):
        tau_plant[i] += acting[i]
    c.force[0], c.force[1] = acting[N], acting[N + 1]
    return SampleStatus.OK


@njit(cache=True)
def sample_laws(c, t, k, row):
    """One whole sample with compiled laws: `pre_sample`, the observer and the
    controller through their function pointers, `post_sample`.  Returns the
    `SampleStatus`; the plant's torques are then in ``c.tau_plant`` (``c.counts[1]`` of
    them)."""
    code = pre_sample(c, t, k, row)
    if code != SampleStatus.OK:
        return code
    N = 2 * c.n
    off = c.off
    if c.has_observer:
        for i in range(c.obs_idx.shape[0]):
            c.y_obs[i] = c.y_used[c.obs_idx[i]]
        failed = c.observer(t, c.y_obs, c.last_tau[:c.counts[1]], c.o_ints, c.o_reals,
                            c.o_state, c.o_mi, c.o_mr, c.o_wc, c.o_wr, c.x_hat)
        for i in range(N):
            row[off[Group.XHAT] + i] = c.x_hat[i]
        if failed != 0:
            return SampleStatus.OBSERVER_FAILED
    fed = c.x_hat if c.use_estimate else c.truth[:N]
    residual = row[off[Group.RESIDUAL]:off[Group.DIST]]
    n_tau = c.controller(t, fed, c.ref, c.c_ints, c.c_reals, c.c_state, c.c_mi, c.c_mr, c.c_wc,
                         c.c_wr, c.tau, residual)
    return post_sample(c, t, n_tau, row)


@njit(cache=True)
def run_compiled(c, rows):
    """The closed loop on a compiled plant (``c.plant``), every sample compiled
    (`sample_laws`), one sample per row of ``rows``: returns the samples done and the
    `SampleStatus` (the offending value in ``c.info[0]``).  No payload force acts on this
    path (``c.p_ext`` stays zero)."""
    c.plant(False, c.tau_plant, c.p_ext, c.p_ints, c.p_reals, c.p_state, c.p_mi, c.p_mr,
            c.p_wc, c.p_wr, c.truth)
    n_samples = rows.shape[0]
    for k in range(n_samples):
        code = sample_laws(c, k * c.Ts, k, rows[k])
        if code != SampleStatus.OK:
            return k, code
        c.plant(True, c.tau_plant[:c.counts[1]], c.p_ext, c.p_ints, c.p_reals, c.p_state,
                c.p_mi, c.p_mr, c.p_wc, c.p_wr, c.truth)
    # the state after the last period is checked too (as the Python loop does)
    return n_samples, check_bounds(c.truth, c.n, c.joints, c.bounds, c.info)
