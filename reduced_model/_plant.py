"""The reduced model used as a plant: fixed-step RK4 on the paper's eq. (2)."""
from __future__ import annotations

import numpy as np

from . import _kernels as kern
from ._model import ArmModel
from ._parameters import ArmParameters
from ._plant_interface import Measurement, TrueState, check_sample_time
from ._sensors import SensorConfig, SensorModel

__all__ = ["ReducedPlant"]


class ReducedPlant:
    """`ArmModel` integrated with classical RK4 at a fixed internal step.

    Torques are held constant over each call of `step` (zero-order hold).  The
    measurement is set by ``sensors`` (default: encoders θ and the modal coordinates q
    read directly, as the paper assumes); noise belongs to the closed loop.

    Parameters
    ----------
    params : ArmParameters, optional
        The arm simulated (the "true" arm of a scenario).
    modes_per_link : (int, int)
        Assumed modes per link of the plant model (1..4 each).
    step : float
        Internal RK4 step [s], default 1 ms.  At 1 ms RK4 resolves the default arm's
        highest mode with 2+2 modes (34 Hz, ω h = 0.21) to ~1e-5 amplitude error
        per period; use 0.25 ms or less with 4 modes per link (up to ~250 Hz).
    sensors : SensorConfig
        What is measured (see `SensorConfig`).
    """

    name = "reduced"

    def __init__(self, params: ArmParameters | None = None, *,
                 modes_per_link: tuple[int, int] = (2, 2), step: float = 1e-3,
                 sensors: SensorConfig = SensorConfig()) -> None:
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"step must be a positive number of seconds, got {step!r}")
        self.model = ArmModel(params, modes_per_link)
        self.h = float(step)
        n = self.model.n
        self._x = np.zeros(2 * n)
        self.sensors = SensorModel(sensors, self.model.mode_shapes, self)
        # Without gauges, quantisation or tip position the measurement is the head of the
        # state vector [θ, q, θ̇, q̇]: read it directly (a third of the per-step cost).
        direct = (sensors.strain_gauges is None and sensors.encoder_resolution == 0
                  and not sensors.tip_position)
        self._direct = (2 * n if sensors.rates else n) if direct else 0
        self._tau = np.zeros(2)
        self._Ts_nsteps = (None, 0)  # (last Ts, its number of internal steps)
        self._steps = 0  # internal steps since reset: time = steps · h without round-off drift
        self._work = self.model.new_workspace()[0]
        self.time = 0.0

    def _measure(self) -> Measurement:
        if self._direct:
            return Measurement(self.time, self.sensors.names, self._x[:self._direct].copy())
        return self.sensors.measure(self.time)

    # --- sensor primitives (see reduced_model._sensors) ---------------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.model.n
        return self._x[0:2].copy(), self._x[n:n + 2].copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.model.n
        return self._x[2:n].copy(), self._x[n + 2:].copy()

    def field_sampler(self, link: int, x, derivative: int):
        """Callable giving w_link^(derivative)(x) = Σ φ^(derivative)(x) q (modal field)."""
        basis = self.model.mode_shapes[link].evaluate(x, derivative).T
        n1 = self.model.modes_per_link[0]
        coords = slice(2, 2 + n1) if link == 0 else slice(2 + n1, self.model.n)
        return lambda: basis @ self._x[coords]

    def tip_positions(self) -> np.ndarray:
        return self.model.tip_position(self._x[:self.model.n])

    def reset(self, state0=None) -> Measurement:
        """Start at ``state0`` = [Q, Q̇] (length 2n) at t = 0; default: rest at Q = 0."""
        n = self.model.n
        if state0 is None:
            self._x[:] = 0.0
        else:
            x0 = np.asarray(state0, dtype=float)
            if x0.shape != (2 * n,) or not np.all(np.isfinite(x0)):
                raise ValueError(f"state0 must be {2 * n} finite numbers [Q, Qdot] in the order "
                                 f"{self.model.state_names}, got shape {x0.shape}")
            self._x[:] = x0
        self._steps = 0
        self.time = 0.0
        return self._measure()

    def step(self, tau, Ts: float) -> Measurement:
        """Hold joint torques ``tau`` (2,) [N m] for ``Ts`` seconds; return y(t + Ts).

        ``tau`` of length n applies generalised forces to every coordinate (the paper's
        idealised, unrealisable input); only the reduced plant accepts it.
        """
        last_Ts, nsteps = self._Ts_nsteps
        if Ts != last_Ts:
            nsteps = check_sample_time(Ts, self.h)
            self._Ts_nsteps = (Ts, nsteps)
        tau = np.asarray(tau, dtype=float)
        if tau.shape == (2,):
            self._tau[:] = tau
            tau_in = self._tau
        elif tau.shape == (self.model.n,):
            tau_in = np.ascontiguousarray(tau)
        else:
            raise ValueError(f"tau must have shape (2,) or ({self.model.n},), got {tau.shape}")
        ints, reals = self.model.packed
        wc, wr = self._work
        kern.rk4_advance_packed(ints, reals, wc, wr, self._x, tau_in, self.h, nsteps)
        self._steps += nsteps
        self.time = self._steps * self.h
        return self._measure()

    @property
    def state(self) -> np.ndarray:
        """Copy of the state [Q, Q̇]."""
        return self._x.copy()

    def truth(self) -> TrueState:
        n, x = self.model.n, self._x
        Q = x[:n]
        return TrueState(
            time=self.time,
            theta=x[0:2].copy(), theta_dot=x[n:n + 2].copy(),
            q=x[2:n].copy(), q_dot=x[n + 2:].copy(),
            tip_positions=self.model.tip_position(Q),
            tip_deflections=self.model.tip_deflection(Q),
            projection_residual=np.zeros(2),
        )
