"""The arm's joints beyond the paper's ideal ones, compiled for the reduced plant: friction
with stiction, a drive (gear compliance with backlash, reflected rotor inertia) and a
first-order torque (current-loop) lag — `ArmParameters`' joint fields, applied as the
truth plant applies them (`plant_exudyn._drives`; docs/theory/joints.rst).

Per joint i (of N, one at each link's root), with the motor torque u_i (the command through its lag):

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

Buffers (allocated once per plant, `new_joint_buffers`): ``jp`` the parameters
(`PARAMETERS` × N joints, entry N·field + joint), ``js`` the state (4N: the friction
modes, the rotor angles and rates, the torques at the lag's output), ``jw`` scratch.
Like the model's kernels, `advance_joints` takes the kinematics as a constant: its
entry points are compiled once per kinematics (`advance_joints_linear`,
`advance_joints_exact`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..dynamics import (bias_forces_into, cholesky_factor_inplace, cholesky_solve_factored,
                        cholesky_solve_inplace, mass_matrix_into, unpack_model,
                        unpack_workspace, vector_view)

__all__ = ["PARAMETERS", "new_joint_buffers", "joints_active", "reset_joints",
           "advance_joints_linear", "advance_joints_exact", "motor_state_into", "lag_step"]

#: The joint fields of `ArmParameters` in ``jp`` (entry N·field + joint; "static" is
#: `Joint.static_friction`, the breakaway level at least the Coulomb level).
PARAMETERS = ("coulomb", "static_friction", "stribeck_velocity", "viscous", "gear_stiffness",
              "gear_damping", "rotor_inertia", "backlash", "torque_time_constant")
_TC, _TS, _VS, _B, _K, _D, _J, _BL, _T = range(len(PARAMETERS))
# ``js`` (N each): friction mode of each joint's sliding coordinate (0 stuck, ±1 slipping
# that way), rotor angle, rotor rate, torque at the lag's output.
_MODE, _ROT, _ROT_RATE, _APPLIED = range(4)


def new_joint_buffers(params, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(jp, js, jw) for the arm ``params`` (an `ArmParameters`) with ``n`` coordinates."""
    N = len(params.joints)
    jp = np.array([getattr(joint, name) for name in PARAMETERS for joint in params.joints])
    return jp, np.zeros(4 * N), np.zeros(_work_length(n, N))


def _work_length(n: int, N: int) -> int:
    """The length of ``jw`` for an arm of ``n`` coordinates and ``N`` joints (`_work`)."""
    return 2 * n + 2 * N * n + 10 * N


@njit(cache=True, inline="always")
def _work(jw, n, N):
    """The scratch arrays in ``jw``: the arm's joint and modal forces (n), the holding
    torques (N), the stuck rows' right-hand sides (N), their rows of M (N n), M⁻¹ G
    (N n), the step's generalised forces (n), the rotors' RK4 stage, sum and trial state
    (2N each), the step's mean motor torques (N) and the lag's output at its end (N)."""
    a = n + 2 * N
    b = a + N * n
    c = b + N * n
    o = c + n
    return (vector_view(jw, 0, n), vector_view(jw, n, N), vector_view(jw, n + N, N),
            vector_view(jw, a, N * n), vector_view(jw, b, N * n), vector_view(jw, c, n),
            vector_view(jw, o, 2 * N), vector_view(jw, o + 2 * N, 2 * N),
            vector_view(jw, o + 4 * N, 2 * N), vector_view(jw, o + 6 * N, N),
            vector_view(jw, o + 7 * N, N))


def joints_active(jp: np.ndarray) -> bool:
    """Whether any joint effect is on (else the plant is the paper's, unchanged)."""
    return bool(np.any(jp != 0.0))


@njit(cache=True, forceinline=True)
def _p(jp, field, i, N):
    """Parameter ``field`` (`PARAMETERS` index) of joint ``i``."""
    return jp[N * field + i]


@njit(cache=True)
def reset_joints(jp, js, x):
    """Joint state for the arm state ``x`` = [Q, Q̇]: rotors on their hubs (gear
    unloaded), every coordinate with dry friction stuck if at rest (else slipping its
    way), the lag's output at zero."""
    n = x.shape[0] // 2
    N = js.shape[0] // 4
    for i in range(N):
        js[N * _ROT + i] = x[i]
        js[N * _ROT_RATE + i] = x[n + i]
        v = x[n + i]
        js[N * _MODE + i] = 0.0 if v == 0.0 else math.copysign(1.0, v)
        js[N * _APPLIED + i] = 0.0


@njit(cache=True)
def motor_state_into(jp, js, x, out):
    """``out`` = [motor angles (N), motor rates (N)]: the rotors where there is a drive,
    the joints themselves where there is none."""
    n = x.shape[0] // 2
    N = js.shape[0] // 4
    for i in range(N):
        drive = _p(jp, _K, i, N) > 0.0
        out[i] = js[N * _ROT + i] if drive else x[i]
        out[N + i] = js[N * _ROT_RATE + i] if drive else x[n + i]


@njit(cache=True)
def lag_step(command, start, T, h):
    """(mean, end) over a step ``h`` of the first-order lag (time constant ``T``; 0:
    none) from ``start`` towards the held ``command``: u(t) = c + (u0 − c) e^{−t/T}."""
    if T <= 0.0:
        return command, command
    a = math.exp(-h / T)
    return command + (start - command) * T / h * (1.0 - a), command + (start - command) * a


@njit(cache=True, forceinline=True)
def _friction(jp, i, N, mode, v):
    """Friction torque of joint ``i``'s sliding coordinate moving at ``v`` in ``mode``
    (±1; 0 with no dry friction: viscous only)."""
    f = -_p(jp, _B, i, N) * v
    if mode != 0.0:
        tc, ts, vs = _p(jp, _TC, i, N), _p(jp, _TS, i, N), _p(jp, _VS, i, N)
        level = tc + (ts - tc) * math.exp(-abs(v) / vs) if ts > tc else tc
        f -= mode * level
    return f


@njit(cache=True, forceinline=True)
def _gear(jp, i, N, deflection, rate):
    """Gear torque on the hub of joint ``i`` (the rotor gets its reaction)."""
    half = 0.5 * _p(jp, _BL, i, N)
    if deflection > half:
        d = deflection - half
    elif deflection < -half:
        d = deflection + half
    else:
        return 0.0
    return _p(jp, _K, i, N) * d + _p(jp, _D, i, N) * rate


@njit(cache=True, forceinline=True)
def _arm_stuck(jp, js, i, N):
    """Whether joint ``i``'s arm coordinate is held by its friction (dry friction, stuck,
    no drive: with a drive the rotor sticks, not the arm)."""
    return _p(jp, _TS, i, N) > 0.0 and js[N * _MODE + i] == 0.0 and _p(jp, _K, i, N) == 0.0


@njit(cache=True, inline="always")
def _derivatives(d, x, rot, u, ext, xdot, rdot, lam, ws, jp, js, jw, exact):
    """ẋ of the arm and ṙ of the rotors ``rot`` = [θm, θ̇m] under the motor torques ``u``
    and the generalised forces ``ext``, the friction modes of ``js`` held; ``lam``
    receives the holding torque of each stuck coordinate (module docstring)."""
    n = x.shape[0] // 2
    N = d.links
    tq, _, rhs, rows = _work(jw, n, N)[:4]
    for i in range(n):
        xdot[i] = x[n + i]
        tq[i] = ext[i]
    for i in range(N):
        lam[i] = 0.0
        dry = _p(jp, _TS, i, N) > 0.0
        mode = js[N * _MODE + i] if dry else 0.0
        stuck = dry and mode == 0.0
        rdot[i] = rot[N + i]
        rdot[N + i] = 0.0
        if _p(jp, _K, i, N) > 0.0:
            g = _gear(jp, i, N, rot[i] - x[i], rot[N + i] - x[n + i])
            tq[i] += g
            if stuck:
                lam[i] = g - u[i]
            else:
                rdot[N + i] = (u[i] - g + _friction(jp, i, N, mode, rot[N + i])) \
                    / _p(jp, _J, i, N)
        else:
            tq[i] += u[i]
            if not stuck:
                tq[i] += _friction(jp, i, N, mode, x[n + i])
    Qdd = xdot[n:]
    f = ws.f
    bias_forces_into(d, x[:n], x[n:], f, ws, exact)
    for i in range(n):
        Qdd[i] = tq[i] - f[i]
    M = ws.M
    for j in range(N):  # rows of stuck joints kept for λ, then removed from the system
        if _arm_stuck(jp, js, j, N):
            for k in range(n):
                rows[j * n + k] = M[j, k]
            rhs[j] = Qdd[j]
    for j in range(N):
        if _arm_stuck(jp, js, j, N):
            for k in range(n):
                M[j, k] = 0.0
                M[k, j] = 0.0
            M[j, j] = 1.0
            Qdd[j] = 0.0
    if not cholesky_solve_inplace(M, Qdd):
        Qdd[:] = np.nan
        return
    for j in range(N):
        if _arm_stuck(jp, js, j, N):
            acc = 0.0
            for k in range(n):
                acc += rows[j * n + k] * Qdd[k]
            lam[j] = acc - rhs[j]


@njit(cache=True, inline="always")
def _stop(d, x, rot, jp, js, jw, ws, exact):
    """End of a step: every slipping coordinate whose velocity reached zero or reversed
    sticks; the arm's velocities are projected onto the stuck joints' constraints in
    the mass metric (the impulse the constrained arm takes), a rotor's set to zero."""
    n = x.shape[0] // 2
    N = d.links
    project = False
    for i in range(N):
        mode = js[N * _MODE + i]
        if _p(jp, _TS, i, N) == 0.0 or mode == 0.0:
            continue
        drive = _p(jp, _K, i, N) > 0.0
        v = rot[N + i] if drive else x[n + i]
        if v * mode <= 0.0:
            js[N * _MODE + i] = 0.0
            if drive:
                rot[N + i] = 0.0
            else:
                project = True
    if project:
        if exact:
            _project_stuck_exact(d.ints, d.reals, ws.wc, ws.wr, x, jp, js, jw)
        else:
            _project_stuck_linear(d.ints, d.reals, ws.wc, ws.wr, x, jp, js, jw)


@njit(cache=True, inline="always")
def _project_stuck(d, x, jp, js, jw, ws, exact):
    """Q̇ −= Y S⁻¹ Gᵀ Q̇, Y = M⁻¹ G, S = Gᵀ Y, G the columns e_j of the stuck joints."""
    n = x.shape[0] // 2
    N = d.links
    mass_matrix_into(d, x[:n], ws.M, ws, exact)
    if not cholesky_factor_inplace(ws.M):
        x[n:] = np.nan
        return
    Y = _work(jw, n, N)[4]
    stuck = 0  # the stuck arm joints, Y's columns in their order
    for j in range(N):
        if _arm_stuck(jp, js, j, N):
            col = Y[stuck * n:(stuck + 1) * n]
            col[:] = 0.0
            col[j] = 1.0
            cholesky_solve_factored(ws.M, col)
            stuck += 1
    S, z = _work(jw, n, N)[3], _work(jw, n, N)[2]  # S (stuck²) and z (stuck) as scratch
    k = 0
    for j in range(N):
        if _arm_stuck(jp, js, j, N):
            l_ = 0
            for i in range(N):
                if _arm_stuck(jp, js, i, N):
                    S[k * stuck + l_] = Y[l_ * n + j]
                    l_ += 1
            z[k] = x[n + j]
            k += 1
    if stuck == 1:
        z[0] = z[0] / S[0]
    elif stuck == 2:  # S_kl = Y_l[j_k]; the closed form on S = [[a, b], [c, e]]
        a, b, c, e = S[0], S[2], S[1], S[3]
        g0, g1 = z[0], z[1]
        det = a * e - b * c
        z[0], z[1] = (e * g0 - b * g1) / det, (a * g1 - c * g0) / det
    else:
        Sm = S[:stuck * stuck].reshape((stuck, stuck))
        cholesky_solve_inplace(Sm, z[:stuck])
    for k_ in range(n):
        acc = 0.0
        for i in range(stuck):
            acc += Y[i * n + k_] * z[i]
        x[n + k_] -= acc
    for j in range(N):  # exactly still: round-off must not start a creep
        if _arm_stuck(jp, js, j, N):
            x[n + j] = 0.0


@njit(cache=True)
def _project_stuck_linear(ints, reals, wc, wr, x, jp, js, jw):
    """`_project_stuck` (called, not inlined: rare, and the mass matrix it forms is a
    large piece of machine code)."""
    _project_stuck(unpack_model(ints, reals), x, jp, js, jw, unpack_workspace(ints, wc, wr),
                   False)


@njit(cache=True)
def _project_stuck_exact(ints, reals, wc, wr, x, jp, js, jw):
    _project_stuck(unpack_model(ints, reals), x, jp, js, jw, unpack_workspace(ints, wc, wr),
                   True)


@njit(cache=True, inline="always")
def advance_joints(d, x, tau, ext, h, nsteps, ws, jp, js, jw, exact):
    """Advance the arm ``x`` and the joint state ``js`` by ``nsteps`` RK4 steps of ``h``
    with the motor commands ``tau[:N]`` held (``tau[N:]``: generalised forces on the
    modal coordinates, the idealised PBC's) and the generalised forces ``ext`` (n,)."""
    m = x.shape[0]
    n = m // 2
    N = d.links
    k, acc, xt = ws.k1, ws.k2, ws.xt
    _, lam, _, _, _, fext, rk, racc, rt, u, u_end = _work(jw, n, N)
    rot = vector_view(js, N * _ROT, 2 * N)
    for _ in range(nsteps):
        for i in range(N):  # the lag: this step's mean torque and its value at the end
            u[i], u_end[i] = lag_step(tau[i], js[N * _APPLIED + i], _p(jp, _T, i, N), h)
        for i in range(n):  # generalised forces of the step: ext plus the modal inputs
            fext[i] = ext[i] + (tau[i] if N <= i < tau.shape[0] else 0.0)
        for i in range(m):
            xt[i] = x[i]
            acc[i] = 0.0
        for i in range(2 * N):
            rt[i] = rot[i]
            racc[i] = 0.0
        # One call site of the (inlined) derivatives, a third less machine code to
        # compile: the first stage is evaluated again, up to N + 2 times in all, while
        # stuck coordinates whose holding torque exceeds τs slip.
        stage = evaluations = 0
        while stage < 4:
            _derivatives(d, xt, rt, u, fext, k, rk, lam, ws, jp, js, jw, exact)
            if stage == 0:
                evaluations += 1
                released = False
                for i in range(N):
                    if _p(jp, _TS, i, N) > 0.0 and js[N * _MODE + i] == 0.0 and \
                            abs(lam[i]) > _p(jp, _TS, i, N):
                        js[N * _MODE + i] = -math.copysign(1.0, lam[i])
                        released = True
                if released and evaluations < N + 2:
                    continue
            weight = 2.0 if stage == 1 or stage == 2 else 1.0
            step = h if stage == 2 else 0.5 * h
            for i in range(m):
                acc[i] += weight * k[i]
                xt[i] = x[i] + step * k[i]
            for i in range(2 * N):
                racc[i] += weight * rk[i]
                rt[i] = rot[i] + step * rk[i]
            stage += 1
        for i in range(m):
            x[i] += h / 6.0 * acc[i]
        for i in range(2 * N):
            rot[i] += h / 6.0 * racc[i]
        for i in range(N):
            js[N * _APPLIED + i] = u_end[i]
        _stop(d, x, rot, jp, js, jw, ws, exact)


@njit(cache=True, inline="always")
def _borrow(a):
    """``a`` borrowed (`reduced_model.dynamics.vector_view`): it holds no reference."""
    return vector_view(a, 0, a.shape[0])


@njit(cache=True)
def advance_joints_linear(ints, reals, wc, wr, x, tau, ext, h, nsteps, jp, js, jw):
    """`advance_joints` on packed buffers (the paper's kinematics), every one borrowed:
    numba counts a reference to each array argument of each function it inlines, an
    atomic increment and decrement per argument, call and stage (a borrowed view has no
    count to change)."""
    b = _borrow
    advance_joints(unpack_model(b(ints), b(reals)), b(x), b(tau), b(ext), h, nsteps,
                   unpack_workspace(b(ints), b(wc), b(wr)), b(jp), b(js), b(jw), False)


@njit(cache=True)
def advance_joints_exact(ints, reals, wc, wr, x, tau, ext, h, nsteps, jp, js, jw):
    """`advance_joints` on packed buffers (exact kinematics), every one borrowed."""
    b = _borrow
    advance_joints(unpack_model(b(ints), b(reals)), b(x), b(tau), b(ext), h, nsteps,
                   unpack_workspace(b(ints), b(wc), b(wr)), b(jp), b(js), b(jw), True)
