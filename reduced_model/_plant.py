"""The reduced model used as a plant: fixed-step RK4 on the paper's eq. (2)."""
from __future__ import annotations

import functools

import numpy as np

from . import _kernels as kern
from ._model import cached_model, validate_modes_per_link
from ._modes import LinkModes, gauss_legendre, weighted_projector
from ._parameters import ArmParameters
from ._plant_base import Plant
from ._plant_interface import Measurement, check_sample_time
from ._sensors import SensorConfig

__all__ = ["ReducedPlant"]


class ReducedPlant(Plant):
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
    modal_basis : (LinkModes, LinkModes), optional
        Mode shapes in which `truth` and the measurement express q (e.g. those of the
        controller's nominal model).  Default: the plant's own.  Otherwise each link's
        modal deflection is projected onto the basis by weighted least squares (the same
        projection as the FE plant's); the link lengths must agree.
    sensors : SensorConfig
        What is measured (see `SensorConfig`).
    """

    name = "reduced"
    role = "reduced"

    def __init__(self, params: ArmParameters | None = None, *,
                 modes_per_link: tuple[int, int] = (2, 2), step: float = 1e-3,
                 modal_basis: tuple[LinkModes, LinkModes] | None = None,
                 sensors: SensorConfig = SensorConfig()) -> None:
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"step must be a positive number of seconds, got {step!r}")
        self.model = cached_model(params if params is not None else ArmParameters(),
                                  validate_modes_per_link(modes_per_link))
        self.h = float(step)
        n = self.model.n
        self._x = np.zeros(2 * n)
        self._f = np.zeros(n)  # generalised forces when a tip force acts
        basis = tuple(modal_basis) if modal_basis is not None else self.model.mode_shapes
        self._basis_map = None if modal_basis is None else _projection(self.model.mode_shapes,
                                                                      basis)
        self._tau = np.zeros(2)
        self._steps = 0  # internal steps since reset: time = steps · h without round-off drift
        self._work = self.model.new_workspace()[0]
        Plant.__init__(self, sensors, basis)

    # --- sensor primitives (see reduced_model._sensors) ---------------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.model.n
        return self._x[0:2].copy(), self._x[n:n + 2].copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) in the modal basis."""
        n = self.model.n
        q, qd = self._x[2:n], self._x[n + 2:]
        if self._basis_map is None:
            return q.copy(), qd.copy()
        return self._basis_map @ q, self._basis_map @ qd

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
        return self.measure()

    def advance(self, tau, Ts: float, tip_force=None) -> None:
        """Hold joint torques ``tau`` (2,) [N m] for ``Ts`` seconds.

        ``tau`` of length n applies generalised forces to every coordinate (the paper's
        idealised, unrealisable input); only the reduced plant accepts it.  ``tip_force``
        (Fx, Fy) [N] in the base frame acts on the payload as generalised forces Jᵀ F,
        with the tip Jacobian J taken at the start of the period.
        """
        nsteps = self.periods(Ts)
        tau = np.asarray(tau, dtype=float)
        if tau.shape == (2,):
            self._tau[:] = tau
            tau_in = self._tau
        elif tau.shape == (self.model.n,):
            tau_in = np.ascontiguousarray(tau)
        else:
            raise ValueError(f"tau must have shape (2,) or ({self.model.n},), got {tau.shape}")
        if tip_force is not None and np.any(tip_force):
            f = self._f
            f[:] = self.model.tip_jacobian(self._x[:self.model.n]).T @ np.asarray(tip_force, float)
            f[:tau_in.shape[0]] += tau_in
            tau_in = f
        ints, reals = self.model.packed
        wc, wr = self._work
        kern.rk4_advance_packed(ints, reals, wc, wr, self._x, tau_in, self.h, nsteps)
        self._steps += nsteps
        self.time = self._steps * self.h

    def compiled_stepping(self) -> dict | None:
        """What a compiled loop needs to step this plant itself (`validation.run._sample.
        run_reduced`): the model's packed buffers, the live state, the step and the map
        to the measurement basis; None where this plant's Python path is needed — a
        measurement that is not the plain state (gauges, quantisation, payload position)."""
        cfg = self.sensors.config
        if cfg.strain_gauges is not None or cfg.encoder_resolution != 0 or cfg.tip_position:
            return None
        basis = np.zeros((0, 0)) if self._basis_map is None else self._basis_map
        return {"model": (*self.model.packed, *self._work), "x": self._x, "h": self.h,
                "basis": np.ascontiguousarray(basis, dtype=float),
                "nsteps": lambda Ts: check_sample_time(Ts, self.h)}

    @property
    def state_size(self) -> int:
        """Length of the state [Q, Q̇] in the plant's own coordinates."""
        return 2 * self.model.n

    @property
    def state(self) -> np.ndarray:
        """Copy of the state [Q, Q̇]."""
        return self._x.copy()

    def truth_into(self, out: np.ndarray) -> None:
        """The truth vector [θ, q, θ̇, q̇ (q in the modal basis), tips, tip deflections,
        0, 0] written into ``out``."""
        n, x = self.model.n, self._x
        if self._basis_map is None:
            out[:2 * n] = x
        else:
            m = 2 + self._basis_map.shape[0]
            out[:2], out[m:m + 2] = x[:2], x[n:n + 2]
            out[2:m] = self._basis_map @ x[2:n]
            out[m + 2:2 * m] = self._basis_map @ x[n + 2:]
        kern.tip_kinematics_packed(*self.model.packed, x[:n], out[-8:-2])
        out[-2:] = 0.0  # a modal field is represented exactly by its own modes


@functools.lru_cache(maxsize=64)
def _projection(own: tuple[LinkModes, LinkModes], basis: tuple[LinkModes, LinkModes]) -> np.ndarray:
    """Block matrix mapping modal coordinates of the mode shapes ``own`` to ``basis``'s
    (cached by the shapes' identity: the models of a sweep are shared, `cached_model`;
    callers must not modify it)."""
    blocks = []
    for link, (b, mine) in enumerate(zip(basis, own)):
        if abs(b.L - mine.L) > 1e-12 * mine.L:
            raise ValueError(f"modal_basis: link {link + 1} has L = {b.L}, the plant "
                             f"L = {mine.L}; the deflection cannot be projected")
        x, w = gauss_legendre(0.0, mine.L)
        blocks.append(weighted_projector(
            b, w_quad=w, basis_quad=b.phi(x).T, basis_tip=np.vstack(b.tip_values),
            target_quad=mine.phi(x).T, target_tip=np.vstack(mine.tip_values)))
    out = np.zeros((sum(p.shape[0] for p in blocks), sum(p.shape[1] for p in blocks)))
    out[:blocks[0].shape[0], :blocks[0].shape[1]] = blocks[0]
    out[blocks[0].shape[0]:, blocks[0].shape[1]:] = blocks[1]
    return out
