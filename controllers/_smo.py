"""The paper's full-order sliding-mode observer, eq. (21)–(36), and two practical variants.

    x̂̇ = f(x̂, τ) + L sign(y − ŷ)                                  (23)–(24)

with f(x, τ) = [Q̇; M⁻¹(B τ − C Q̇ − D Q̇ − K Q)] from the reduced model (not the paper's
row-by-row triangular form, which is the same function).  x = [Q, Q̇] = [P, V].

Variants (one class each, named by their ``kind`` in a scenario):

- ``"smo-paper"``: y = the full state (the paper's y = h(x) = x), sign injection on every
  component.  Each error reaches its sliding band in finite time and then chatters in
  ±Ts·L (discrete sign).
- ``"smo-bl"``: sat((y − ŷ)/ε) instead of sign, with ε = ``boundary_layer``·Ts·L
  per component; inside the layer the discrete correction removes 1/``boundary_layer``
  of the error per step, so the estimate follows y without chattering.
- ``"smo-pos"``: y = positions P only (encoders θ and strain-derived q).  Step by
  step as in the paper's ref. [12] (Barbot, Boukhobza & Djemai 1996): step 1, the
  position injection ν_P = L_P sign(y − P̂) drives P̂ onto y; step 2, once P̂ slides on y,
  the equivalent (low-pass filtered) value ν̄ of ν_P equals the velocity error V − V̂, so
  z = V̂ + ν̄ is a pseudo-measurement of V and the velocity injection is
  L_V sign(z − V̂) = L_V sign(ν̄).  ν̄ is a first-order filter of ν_P with time constant
  ``filter_time``.  Step 2 is gated per coordinate: the velocity injection of coordinate i
  acts only while its position error is on the sliding surface, |y_i − P̂_i| ≤
  ``gate``·Ts·L_P,i (off it, ν_P = ±L_P says nothing about the velocity error).

Gains follow the paper's conditions: (31) L_P > max |V − V̂| (the position errors reach
their sliding surface), (36) L_V > ρ, the bound of the model error |f(x) − f(x̂)| + δ.
In discrete time ρ includes the position chatter ±Ts·L_P seen through each mode's
stiffness, ω_j²·Ts·L_P: for the stiffest default mode (q22, 32 Hz, ω² ≈ 4e4 s⁻²) that is
≈ 20 m/s² > L_V = 2, so its rate error leaves the ±Ts·L_V band (measured ≤ 5e-3 m/s
instead of 2e-3); every other state stays in its band.

Discretisation (stable at Ts = 1 ms): the model part is advanced by RK4 over Ts in
sub-steps of at most 1 ms (the fastest model mode has ω·1 ms = 0.21, far inside RK4's
stability region; explicit Euler would amplify a 34 Hz mode by 2 % per step), and the
injection is held over the period and added as Ts·L·sign(·) — a discrete sliding mode
whose band is ±Ts·L.  Each update first predicts with the torque applied during the
last period, then corrects with the newest measurement.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from reduced_model import ArmModel
from reduced_model.dynamics.entries import advance_exact, advance_linear

from ._compiled import OBSERVER_SIGNATURE, CompiledLaw
from ._gains import arm_gains, control_period, joint_flex_gains

__all__ = ["PaperSMO", "BoundaryLayerSMO", "PositionOnlySMO"]

_MAX_SUBSTEP = 1e-3


def _joint_flex(name: str, value, n_joints: int, n_flex: int) -> np.ndarray:
    """A (joint, flexible) pair, or one number for both, as a gain vector."""
    if np.ndim(value) == 0:
        value = (value, value)
    if len(value) != 2:
        raise ValueError(f"{name}: need (joint, flexible) or one number, got {list(value)!r}")
    return joint_flex_gains(name, value[0], value[1], n_joints, n_flex)


def _positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return float(value)


class _SlidingModeObserver:
    """Eq. (23)–(24) with gains L = diag(L_P, L_V); the variants below fix the injection.

    Gains (every variant's defaults):
    l_position : (joint, flexible)
        L_P [rad/s on θ, m/s on q].  Default (1.0, the arm's rule `arm_gains`: 0.5 on the
        paper's arm): above the largest velocity estimation errors after the initial
        transient (condition 31); position band ±Ts·L_P = 1e-3 rad and 5e-4 m at 1 kHz
        on the paper's arm.
    l_velocity : (joint, flexible)
        L_V [rad/s², m/s²].  Default (5, 2): velocity bands ±5e-3 rad/s and ±2e-3 m/s at
        1 kHz.  Measured on the paper's scenario with noise: L_V = 20 gives a band as
        large as the flexible rates themselves (q̇12 error/signal RMS 0.9 on both plants);
        (5, 2) gives 0.05–0.14; below it condition (36) fails on the FE plant — with
        L_V,flex = 0.5 the reduced model's error ρ exceeds the gain and the q̇11 error grows
        to the size of the signal.
    """

    _variant = 0
    _positions_only = False

    def _setup(self, model: ArmModel, Ts, l_position, l_velocity, boundary_layer=1.0,
               filter_time=1.0, gate=1.0) -> None:
        self.model, self.Ts = model, control_period(Ts)
        n, N = model.n, model.n_joints
        if l_position is None:
            l_position = (1.0, arm_gains(model, self.Ts).l_position_flex)
        self.lp = _joint_flex("l_position", l_position, N, n - N)
        self.lv = _joint_flex("l_velocity", l_velocity, N, n - N)
        self.boundary_layer = _positive("boundary_layer", boundary_layer)
        self.filter_time = _positive("filter_time", filter_time)
        self.gate = _positive("gate", gate)
        nsub = max(1, math.ceil(self.Ts / _MAX_SUBSTEP - 1e-9))  # RK4 sub-steps
        self._kernel = smo_kernel_exact if model.exact else smo_kernel
        self._ints = np.array([nsub, 1, self._variant], dtype=np.int64)  # [.., fresh, ..]
        self._reals = np.concatenate([self.lp, self.lv, [
            self.boundary_layer, min(1.0, self.Ts / self.filter_time), self.gate, self.Ts]])
        self._state = np.zeros(3 * n)  # [x̂, ν̄]
        self._work = model.new_workspace()
        self._x_hat = np.zeros(2 * n)

    @property
    def measured(self) -> tuple[str, ...]:
        """Names of the measurement signals the observer needs, in the order of y."""
        names = self.model.state_names
        return names[:self.model.n] if self._positions_only else names

    def reset(self, x_hat0) -> np.ndarray:
        x0 = np.asarray(x_hat0, dtype=float)
        n2 = 2 * self.model.n
        if x0.shape != (n2,):
            raise ValueError(f"x_hat0 must have shape ({n2},), got {x0.shape}")
        self._state[:n2] = x0
        self._state[n2:] = 0.0
        self._ints[1] = 1  # fresh: the next update only corrects
        return x0.copy()

    def update(self, t: float, y: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Advance the estimate over the last period (torque ``tau``) and correct it with
        ``y`` (in the order of `measured`) measured at ``t``; the first call after `reset`
        only corrects."""
        self._kernel(t, np.ascontiguousarray(y, dtype=float),
                     np.ascontiguousarray(tau, dtype=float), self._ints, self._reals,
                     self._state, *self.model.packed, *self._work, self._x_hat)
        return self._x_hat.copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`), its state copied as it is now."""
        return CompiledLaw.of(self._kernel, OBSERVER_SIGNATURE, self.model, ints=self._ints,
                              reals=self._reals, state=self._state)


class PaperSMO(_SlidingModeObserver):
    """``"smo-paper"``: the paper's observer, sign injection on the full measured state
    (y = x).

    Parameters
    ----------
    model : ArmModel
        The nominal model the estimate is predicted with.
    Ts : float
        The control period [s]: the horizon of each prediction and of the discrete
        injection's band ±Ts·L.
    l_position, l_velocity : (float, float) or float
        L_P [rad/s on θ, m/s on q] and L_V [rad/s², m/s²] as (joint, flexible) gains, or
        one number for both; defaults (1.0, the arm's rule: 0.5 on the paper's arm) and
        (5, 2), chosen as the private base
        class `_SlidingModeObserver` records (conditions (31) and (36) of the paper).

    Examples
    --------
    >>> import numpy as np
    >>> from controllers import PaperSMO
    >>> from reduced_model import ArmModel
    >>> smo = PaperSMO(ArmModel(), Ts=1e-3)
    >>> smo.measured[:3]
    ('theta1', 'theta2', 'q11')
    >>> x0 = np.zeros(12)
    >>> smo.reset(x0 + 0.01).round(3)[:2]
    array([0.01, 0.01])
    >>> x_hat = smo.update(0.0, x0, np.zeros(2))  # the first update only corrects
    >>> bool(np.all(np.abs(x_hat[:2] - 0.01) <= 1e-3 + 1e-12))  # by at most Ts·L_P
    True
    """

    name = "smo-paper"

    def __init__(self, model: ArmModel, *, Ts: float, l_position=None,
                 l_velocity=(5.0, 2.0)):
        self._setup(model, Ts, l_position, l_velocity)


class BoundaryLayerSMO(_SlidingModeObserver):
    """``"smo-bl"``: sat((y − ŷ)/ε) instead of sign, ε = ``boundary_layer``·Ts·L per
    component (inside the layer the estimate follows y without chattering).

    Parameters
    ----------
    model, Ts, l_position, l_velocity
        As `PaperSMO`: the nominal model, the control period [s], the gains L_P, L_V.
    boundary_layer : float
        ε in units of the band Ts·L, > 0 (default 2: inside the layer half the error is
        removed per step).
    """

    name = "smo-bl"
    _variant = 1

    def __init__(self, model: ArmModel, *, Ts: float, l_position=None,
                 l_velocity=(5.0, 2.0), boundary_layer: float = 2.0):
        self._setup(model, Ts, l_position, l_velocity, boundary_layer=boundary_layer)


class PositionOnlySMO(_SlidingModeObserver):
    """``"smo-pos"``: positions measured only; Barbot's step-by-step equivalent injection.

    Parameters
    ----------
    model, Ts, l_position, l_velocity
        As `PaperSMO`: the nominal model, the control period [s], the gains L_P, L_V.
    filter_time : float
        The time constant of the equivalent injection's filter [s], > 0 (default 5 ms:
        averages the sign chatter over 5 samples, fast against the 34 Hz mode's 30 ms
        period).
    gate : float
        The velocity injection of a coordinate acts while its position error is within
        ``gate``·Ts·L_P, > 0 (default 2: twice the discrete sliding band, so the chatter
        and a 1e-4 rad / 1e-5 m noise keep it on).
    """

    name = "smo-pos"
    _variant = 2
    _positions_only = True

    def __init__(self, model: ArmModel, *, Ts: float, l_position=None,
                 l_velocity=(5.0, 2.0), filter_time: float = 5e-3, gate: float = 2.0):
        self._setup(model, Ts, l_position, l_velocity, filter_time=filter_time, gate=gate)


@njit(cache=True, inline="always")
def _smo_update(ints, reals, wc, wr, x, tau, Ts, nsub, predict, y, lp, lv, variant, layer,
                alpha, gate, nu, exact):
    if predict:
        if exact:
            advance_exact(ints, reals, wc, wr, x, tau, Ts / nsub, nsub)
        else:
            advance_linear(ints, reals, wc, wr, x, tau, Ts / nsub, nsub)
    n = x.shape[0] // 2
    if variant == 2:  # position_only: step-by-step equivalent output injection
        for i in range(n):
            err = y[i] - x[i]
            inj = lp[i] * np.sign(err)
            x[i] += Ts * inj
            nu[i] += alpha * (inj - nu[i])
            if abs(err) <= gate * Ts * lp[i]:  # step 2 only on the sliding surface
                x[n + i] += Ts * lv[i] * np.sign(nu[i])
        return
    for i in range(2 * n):
        gain = lp[i] if i < n else lv[i - n]
        err = y[i] - x[i]
        if variant == 0:
            x[i] += Ts * gain * np.sign(err)
        elif gain > 0.0:
            x[i] += Ts * gain * min(max(err / (layer * Ts * gain), -1.0), 1.0)


@njit(cache=True, inline="always")
def _smo(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, exact):
    """Eq. (23)–(24) compiled (`controllers._compiled`): ints = [RK4 sub-steps, fresh,
    variant], reals = [L_P, L_V, boundary layer, filter factor, gate, Ts], state =
    [x̂, ν̄]."""
    N = x_hat.shape[0]
    n = N // 2
    x = state[:N]
    _smo_update(mi, mr, wc, wr, x, tau, reals[2 * n + 3], ints[0], ints[1] == 0, y, reals[:n],
                reals[n:2 * n], ints[2], reals[2 * n], reals[2 * n + 1], reals[2 * n + 2],
                state[N:N + n], exact)
    ints[1] = 0  # no longer fresh: later calls predict
    for i in range(N):
        x_hat[i] = x[i]
    return 0


@njit(cache=True)
def smo_kernel(t, y, tau, ints, reals, state, mi, mr, wc, wr, x_hat):
    """`_smo` on a model with the paper's kinematics."""
    return _smo(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, False)


@njit(cache=True)
def smo_kernel_exact(t, y, tau, ints, reals, state, mi, mr, wc, wr, x_hat):
    """`_smo` on a model with exact kinematics."""
    return _smo(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, True)
