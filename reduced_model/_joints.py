"""The arm's joints beyond the paper's ideal ones, compiled for the reduced plant: friction
with stiction, a drive (gear compliance with backlash, reflected rotor inertia) and a
first-order torque (current-loop) lag — `ArmParameters`' joint fields, applied as the
truth plant applies them (`plant_exudyn._drives`; docs/theory/joints.rst).

Per joint i, with the motor torque u_i (the command through its lag):

- no drive: the arm's joint coordinate θ_i receives u_i + f_i, f_i its friction;
- a drive: a rotor θm_i of inertia B_i (reflected to the link side, its kinetic energy
  ½ B θ̇m² relative to the stator: Spong's model of a geared motor) receives
  u_i − τg_i + f_i, the hub θ_i the gear torque τg_i = k·dz(θm − θ) + d·(θ̇m − θ̇),
  dz a dead zone of ±backlash/2 (no torque, no damping, inside it).

Friction is the same law on both plants: *stuck*, the coordinate does not move and the
friction holds whatever torque keeps it still, up to the breakaway level τs; *slipping*
in direction s, f = −s (τc + (τs − τc) e^{−|v|/v_s}) − b v.  Here a stuck coordinate
is an exact constraint (its row removed from M Q̈ = …, the holding torque λ its
multiplier): explicit RK4 cannot integrate a stiff bristle at a 1 ms step.  The mode
is decided per internal step: at its start, a stuck coordinate whose holding torque
exceeds τs slips (direction −sign λ); at its end, a slipping coordinate whose velocity
reached zero or reversed sticks, its velocity set to zero by the impulse that the
constrained arm takes (a projection in the mass metric: it only removes energy).
Between switches the step is RK4 on a smooth right-hand side; a switch costs an error
set by where within its step it fell (bench/bench_joints.py measures the truth plant's).

The torque lag: over each internal step the motor torque is the exact mean of the lag's
response to the held command, u(t) = c + (u0 − c) e^{−t/T}, so both plants apply the
same piecewise-constant torque (second order in the step against the continuous lag).

Buffers (allocated once per plant, `reduced_model._joint_pointers.new_joint_buffers`):
``jp`` the parameters (`PARAMETERS` × 2 joints), ``js`` the state (`STATE`: the friction
modes, the rotor angles and rates, the torques at the lag's output), ``jw`` scratch.
Plants and loops advance the joints through `reduced_model._joint_pointers`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _kernels as kern
from ._cholesky import cholesky_factor_inplace, cholesky_solve_factored, cholesky_solve_inplace

__all__ = ["PARAMETERS", "STATE", "work_length", "joints_active", "reset_joints",
           "advance_joints", "motor_state_into", "lag_step"]

#: The joint fields of `ArmParameters` in ``jp`` (entry 2·field + joint).
PARAMETERS = ("coulomb", "static", "stribeck_velocity", "viscous", "gear_stiffness",
              "gear_damping", "rotor_inertia", "backlash", "torque_time_constant")
_TC, _TS, _VS, _B, _K, _D, _J, _BL, _T = (2 * i for i in range(len(PARAMETERS)))
# ``js``: friction mode of each joint's sliding coordinate (0 stuck, ±1 slipping that
# way), rotor angle, rotor rate, torque at the lag's output.
_MODE, _ROT, _ROT_RATE, _APPLIED = 0, 2, 4, 6
STATE = 8


@njit(cache=True, inline="always")
def work_length(n):
    """The length of ``jw`` for an arm of ``n`` coordinates (`_work`)."""
    return 6 * n + 20


@njit(cache=True, inline="always")
def _work(jw, n):
    """The scratch arrays in ``jw``: the arm's joint and modal forces (n), the holding
    torques (2), the stuck rows' right-hand sides (2), their rows of M (2n), M⁻¹ G (2n),
    the step's generalised forces (n), the rotors' RK4 stage, sum and trial state (4
    each), the step's mean motor torques (2) and the lag's output at its end (2)."""
    o = 6 * n + 4
    return (jw[:n], jw[n:n + 2], jw[n + 2:n + 4], jw[n + 4:3 * n + 4], jw[3 * n + 4:5 * n + 4],
            jw[5 * n + 4:o], jw[o:o + 4], jw[o + 4:o + 8], jw[o + 8:o + 12],
            jw[o + 12:o + 14], jw[o + 14:o + 16])


def joints_active(jp: np.ndarray) -> bool:
    """Whether any joint effect is on (else the plant is the paper's, unchanged)."""
    return bool(np.any(jp != 0.0))


@njit(cache=True)
def reset_joints(jp, js, x):
    """Joint state for the arm state ``x`` = [Q, Q̇]: rotors on their hubs (gear
    unloaded), every coordinate with dry friction stuck if at rest (else slipping its
    way), the lag's output at zero."""
    n = x.shape[0] // 2
    for i in range(2):
        js[_ROT + i] = x[i]
        js[_ROT_RATE + i] = x[n + i]
        v = x[n + i]
        js[_MODE + i] = 0.0 if v == 0.0 else math.copysign(1.0, v)
        js[_APPLIED + i] = 0.0


@njit(cache=True)
def motor_state_into(jp, js, x, out):
    """``out`` = [motor angle 1, 2, motor rate 1, 2]: the rotors where there is a drive,
    the joints themselves where there is none."""
    n = x.shape[0] // 2
    for i in range(2):
        drive = jp[_K + i] > 0.0
        out[i] = js[_ROT + i] if drive else x[i]
        out[2 + i] = js[_ROT_RATE + i] if drive else x[n + i]


@njit(cache=True)
def lag_step(command, start, T, h):
    """(mean, end) over a step ``h`` of the first-order lag (time constant ``T``; 0:
    none) from ``start`` towards the held ``command``: u(t) = c + (u0 − c) e^{−t/T}."""
    if T <= 0.0:
        return command, command
    a = math.exp(-h / T)
    return command + (start - command) * T / h * (1.0 - a), command + (start - command) * a


@njit(cache=True, inline="always")
def _friction(jp, i, mode, v):
    """Friction torque of joint ``i``'s sliding coordinate moving at ``v`` in ``mode``
    (±1; 0 with no dry friction: viscous only)."""
    f = -jp[_B + i] * v
    if mode != 0.0:
        tc, ts, vs = jp[_TC + i], jp[_TS + i], jp[_VS + i]
        level = tc + (ts - tc) * math.exp(-abs(v) / vs) if ts > tc else tc
        f -= mode * level
    return f


@njit(cache=True, inline="always")
def _gear(jp, i, deflection, rate):
    """Gear torque on the hub of joint ``i`` (the rotor gets its reaction)."""
    half = 0.5 * jp[_BL + i]
    if deflection > half:
        d = deflection - half
    elif deflection < -half:
        d = deflection + half
    else:
        return 0.0
    return jp[_K + i] * d + jp[_D + i] * rate


@njit(cache=True, inline="always")
def _derivatives(d, x, rot, u, ext, xdot, rdot, lam, ws, jp, js, jw):
    """ẋ of the arm and ṙ of the rotors ``rot`` = [θm, θ̇m] under the motor torques ``u``
    and the generalised forces ``ext``, the friction modes of ``js`` held; ``lam``
    receives the holding torque of each stuck coordinate (module docstring)."""
    n = x.shape[0] // 2
    tq, _, rhs, rows = _work(jw, n)[:4]
    for i in range(n):
        xdot[i] = x[n + i]
        tq[i] = ext[i]
    stuck0 = stuck1 = False  # arm joints held by their friction
    for i in range(2):
        lam[i] = 0.0
        dry = jp[_TS + i] > 0.0
        mode = js[_MODE + i] if dry else 0.0
        stuck = dry and mode == 0.0
        rdot[i] = rot[2 + i]
        rdot[2 + i] = 0.0
        if jp[_K + i] > 0.0:
            g = _gear(jp, i, rot[i] - x[i], rot[2 + i] - x[n + i])
            tq[i] += g
            if stuck:
                lam[i] = g - u[i]
            else:
                rdot[2 + i] = (u[i] - g + _friction(jp, i, mode, rot[2 + i])) / jp[_J + i]
        else:
            tq[i] += u[i]
            if stuck:
                stuck0, stuck1 = stuck0 or i == 0, stuck1 or i == 1
            else:
                tq[i] += _friction(jp, i, mode, x[n + i])
    Qdd = xdot[n:]
    f = ws.f
    kern.bias_forces_into(d, x[:n], x[n:], f, ws)
    for i in range(n):
        Qdd[i] = tq[i] - f[i]
    M = ws.M
    for j in range(2):  # rows of stuck joints kept for λ, then removed from the system
        if stuck0 if j == 0 else stuck1:
            for k in range(n):
                rows[j * n + k] = M[j, k]
            rhs[j] = Qdd[j]
    for j in range(2):
        if stuck0 if j == 0 else stuck1:
            for k in range(n):
                M[j, k] = 0.0
                M[k, j] = 0.0
            M[j, j] = 1.0
            Qdd[j] = 0.0
    if not cholesky_solve_inplace(M, Qdd):
        Qdd[:] = np.nan
        return
    for j in range(2):
        if stuck0 if j == 0 else stuck1:
            acc = 0.0
            for k in range(n):
                acc += rows[j * n + k] * Qdd[k]
            lam[j] = acc - rhs[j]


@njit(cache=True, inline="always")
def _stop(d, x, rot, jp, js, jw, ws):
    """End of a step: every slipping coordinate whose velocity reached zero or reversed
    sticks; the arm's velocities are projected onto the stuck joints' constraints in
    the mass metric (the impulse the constrained arm takes), a rotor's set to zero."""
    n = x.shape[0] // 2
    project = False
    for i in range(2):
        mode = js[_MODE + i]
        if jp[_TS + i] == 0.0 or mode == 0.0:
            continue
        drive = jp[_K + i] > 0.0
        v = rot[2 + i] if drive else x[n + i]
        if v * mode <= 0.0:
            js[_MODE + i] = 0.0
            if drive:
                rot[2 + i] = 0.0
            else:
                project = True
    if project:
        _project_stuck(d, x, jp, js, jw, ws)


@njit(cache=True)
def _project_stuck(d, x, jp, js, jw, ws):
    """Q̇ −= Y S⁻¹ Gᵀ Q̇, Y = M⁻¹ G, S = Gᵀ Y, G the columns e_j of the stuck joints
    (called, not inlined: rare, and the mass matrix it forms is a large piece of
    machine code)."""
    n = x.shape[0] // 2
    kern.mass_matrix_into(d, x[:n], ws.M, ws)
    if not cholesky_factor_inplace(ws.M):
        x[n:] = np.nan
        return
    Y = _work(jw, n)[4]
    first = last = -1  # the stuck arm joints
    for j in range(2):
        if jp[_TS + j] > 0.0 and js[_MODE + j] == 0.0 and jp[_K + j] == 0.0:
            col = Y[n:] if first >= 0 else Y[:n]
            col[:] = 0.0
            col[j] = 1.0
            cholesky_solve_factored(ws.M, col)
            if first < 0:
                first = j
            last = j
    if first == last:
        z0 = x[n + first] / Y[first]
        for k in range(n):
            x[n + k] -= Y[k] * z0
    else:
        a, b = Y[first], Y[last]  # S = [[a, b], [c, e]]
        c, e = Y[n + first], Y[n + last]
        g0, g1 = x[n + first], x[n + last]
        det = a * e - b * c
        z0, z1 = (e * g0 - b * g1) / det, (a * g1 - c * g0) / det
        for k in range(n):
            x[n + k] -= Y[k] * z0 + Y[n + k] * z1
    for j in range(2):  # exactly still: round-off must not start a creep
        if jp[_TS + j] > 0.0 and js[_MODE + j] == 0.0 and jp[_K + j] == 0.0:
            x[n + j] = 0.0


@njit(cache=True)
def advance_joints(d, x, tau, ext, h, nsteps, ws, jp, js, jw):
    """Advance the arm ``x`` and the joint state ``js`` by ``nsteps`` RK4 steps of ``h``
    with the motor commands ``tau[:2]`` held (``tau[2:]``: generalised forces on the
    modal coordinates, the idealised PBC's) and the generalised forces ``ext`` (n,)."""
    m = x.shape[0]
    n = m // 2
    k, acc, xt = ws.k1, ws.k2, ws.xt
    _, lam, _, _, _, fext, rk, racc, rt, u, u_end = _work(jw, n)
    rot = js[_ROT:_ROT + 4]
    for _ in range(nsteps):
        for i in range(2):  # the lag: this step's mean torque and its value at the end
            u[i], u_end[i] = lag_step(tau[i], js[_APPLIED + i], jp[_T + i], h)
        for i in range(n):  # generalised forces of the step: ext plus the modal inputs
            fext[i] = ext[i] + (tau[i] if 2 <= i < tau.shape[0] else 0.0)
        for i in range(m):
            xt[i] = x[i]
            acc[i] = 0.0
        for i in range(4):
            rt[i] = rot[i]
            racc[i] = 0.0
        # One call site of the (inlined) derivatives, a third less machine code to
        # compile: the first stage is evaluated again, up to 4 times in all, while stuck
        # coordinates whose holding torque exceeds τs slip.
        stage = evaluations = 0
        while stage < 4:
            _derivatives(d, xt, rt, u, fext, k, rk, lam, ws, jp, js, jw)
            if stage == 0:
                evaluations += 1
                released = False
                for i in range(2):
                    if jp[_TS + i] > 0.0 and js[_MODE + i] == 0.0 and \
                            abs(lam[i]) > jp[_TS + i]:
                        js[_MODE + i] = -math.copysign(1.0, lam[i])
                        released = True
                if released and evaluations < 4:
                    continue
            weight = 2.0 if stage == 1 or stage == 2 else 1.0
            step = h if stage == 2 else 0.5 * h
            for i in range(m):
                acc[i] += weight * k[i]
                xt[i] = x[i] + step * k[i]
            for i in range(4):
                racc[i] += weight * rk[i]
                rt[i] = rot[i] + step * rk[i]
            stage += 1
        for i in range(m):
            x[i] += h / 6.0 * acc[i]
        for i in range(4):
            rot[i] += h / 6.0 * racc[i]
        for i in range(2):
            js[_APPLIED + i] = u_end[i]
        _stop(d, x, rot, jp, js, jw, ws)
