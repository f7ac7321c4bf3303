"""The reduced model used as a plant: fixed-step RK4 on the paper's eq. (2)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _kernels as kern
from ._joint_pointers import advance_joints_packed, new_joint_buffers
from ._joints import joints_active, motor_state_into, reset_joints
from ._linear import reduced_linear_model
from ._model import ArmModel, cached_model, validate_kinematics, validate_modes_per_link
from ._inextensible import readout_matrix
from ._modes import projection
from ._readout import modal_readout_into
from ._parameters import ArmParameters, FieldError
from ._plant_base import Plant, PlantSettings
from ._plant_interface import check_sample_time
from ._sensors import SensorConfig

__all__ = ["ReducedPlant", "positive_step"]


class ReducedPlant(Plant):
    """`ArmModel` integrated with classical RK4 at a fixed internal step
    (``kind = "reduced"``: the paper's model as the plant).

    Torques are held constant over each call of `step` (zero-order hold).  The
    measurement is set by ``sensors`` (default: encoders θ and the modal coordinates q
    read directly, as the paper assumes); noise belongs to the closed loop.  The joints
    of ``params`` (friction, drives, torque lag: `reduced_model._joints`) act as on the
    truth plant; with all of them off the plant is the paper's model.

    Parameters
    ----------
    params : ArmParameters, optional
        The arm simulated (the "true" arm of a scenario).
    model : ArmModel, optional
        The model whose mode shapes `truth` and the measurement express q in (the
        controller's nominal model).  Default, or a model of the same arm and order: the
        plant's own.  Otherwise each link's modal deflection is projected onto its modes
        by weighted least squares (the same projection as the FE plant's); the link
        lengths must agree.
    sensors : SensorConfig
        What is measured (see `SensorConfig`).
    modes_per_link : (int, int)
        Assumed modes per link of the plant model (1..4 each).
    step : float
        Internal RK4 step [s], default 1 ms.  At 1 ms RK4 resolves the default arm's
        highest mode with 2+2 modes (34 Hz, ω h = 0.21) to ~1e-5 amplitude error
        per period; use 0.25 ms or less with 4 modes per link (up to ~250 Hz).
    kinematics : {"linear", "exact"}
        The paper's linear kinematics (default) or exact inextensible kinematics
        (`ArmModel`).
    """

    role = "reduced"
    label = "reduced plant"
    actuated = 0  # any: two joint torques, or n generalised forces

    @dataclass(frozen=True)
    class Settings(PlantSettings):
        """``kind = "reduced"``: the paper's model as the plant (fixed-step RK4).

        Parameters
        ----------
        kind : {"reduced"}
            Selects this plant.
        modes_per_link : (int, int)
            The plant's own model order, assumed modes of link 1 and link 2 (1..4 each).
        step : float
            Internal RK4 step [s]; ``Ts`` must be a whole multiple of it.
        kinematics : {"linear", "exact"}
            How a link's points follow its modal deflection: the paper's linear
            kinematics, or the exact inextensible centreline (foreshortening included;
            the geometrically exact FE arm's, `reduced_model.ArmModel`).
        """

        kind: str = "reduced"
        modes_per_link: tuple[int, int] = (2, 2)
        step: float = 1e-3
        kinematics: str = "linear"

        def __post_init__(self):
            if self.kind != "reduced":
                raise FieldError("plant", "kind", f"must be 'reduced', got {self.kind!r}")
            try:
                validate_modes_per_link(self.modes_per_link)
            except ValueError:
                raise FieldError("plant", "modes_per_link", "must be two integers in 1..4, "
                                 f"got {list(self.modes_per_link)!r}") from None
            positive_step(self.step)
            try:
                validate_kinematics(self.kinematics)
            except ValueError as exc:
                raise FieldError("plant", "kinematics", str(exc).removeprefix(
                    "kinematics ")) from None

        def step_cost(self) -> float:
            return 1e-4  # RK4 of 2n states, pessimistic

        def linear_model(self, params, *, theta, model):
            """The plant's own model linearised at ``theta``, its q outputs in ``model``'s
            mode shapes (as the plant reports them)."""
            own = cached_model(params, tuple(self.modes_per_link), self.kinematics)
            same = model.params == params and model.modes_per_link == own.modes_per_link
            return reduced_linear_model(own, theta=theta,
                                        modal_basis=None if same else model.mode_shapes)

    def __init__(self, params: ArmParameters | None = None, *, model: ArmModel | None = None,
                 sensors: SensorConfig = SensorConfig(),
                 modes_per_link: tuple[int, int] = (2, 2), step: float = 1e-3,
                 kinematics: str = "linear") -> None:
        params = params if params is not None else ArmParameters()
        self.model = cached_model(params, validate_modes_per_link(modes_per_link),
                                  validate_kinematics(kinematics))
        n = self.model.n
        self._x = np.zeros(2 * n)
        self._f = np.zeros(n)  # generalised forces when a tip force acts
        own = model is None or (model.params == params
                                and model.modes_per_link == self.model.modes_per_link)
        basis = self.model.mode_shapes if own else model.mode_shapes
        self._basis_map = None if own else projection(self.model.mode_shapes, basis)
        #: The map to the measured q (`reduced_model._readout`): the basis map, or the
        #: exact kinematics' readout of its centreline.
        self._readout = readout_matrix(self.model.links, basis) if self.model.links else (
            np.zeros((0, 0)) if own else self._basis_map)
        self._tau = np.zeros(2)
        self._work = self.model.new_workspace()[0]
        self._joints = new_joint_buffers(params, n)
        self._joints_on = joints_active(self._joints[0])
        self.encoder_side = tuple("motor" if params.has_drive(i) else "link" for i in (1, 2))
        Plant.__init__(self, sensors, basis, step)

    # --- sensor primitives (see reduced_model._sensors) ---------------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.model.n
        return self._x[0:2].copy(), self._x[n:n + 2].copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) in the modal basis (exact kinematics: of the centreline, as the FE
        plant reads its own, `reduced_model._readout`)."""
        n = self.model.n
        q, qd = self._x[2:n], self._x[n + 2:]
        if self.model.links:
            m = sum(b.n for b in self.modal_basis)
            out = np.empty(m), np.empty(m)
            modal_readout_into(*self.model.packed, self._readout, self._x, *out)
            return out
        if self._basis_map is None:
            return q.copy(), qd.copy()
        return self._basis_map @ q, self._basis_map @ qd

    def field_sampler(self, link: int, x, derivative: int):
        """Callable giving w_link^(derivative)(x) = Σ φ^(derivative)(x) q (modal field);
        with exact kinematics the centreline's transverse position (derivative 0) or its
        curvature (2)."""
        n1 = self.model.modes_per_link[0]
        coords = slice(2, 2 + n1) if link == 0 else slice(2 + n1, self.model.n)
        if self.model.kinematics == "exact":
            if derivative not in (0, 2):
                raise ValueError(f"derivative must be 0 or 2, got {derivative}")
            curve = self.model.links[link]
            field = curve.transverse if derivative == 0 else curve.curvature
            return lambda: field(x, self._x[coords])
        basis = self.model.mode_shapes[link].evaluate(x, derivative).T
        return lambda: basis @ self._x[coords]

    def tip_positions(self) -> np.ndarray:
        return self.model.tip_position(self._x[:self.model.n])

    def _reset(self, x0: np.ndarray) -> None:
        """Start at ``x0`` = [Q, Q̇] in the plant's own coordinates."""
        self._x[:] = x0
        reset_joints(self._joints[0], self._joints[1], self._x)

    def _advance(self, tau: np.ndarray, steps: int, tip_force) -> None:
        """Hold ``tau`` (2 joint torques, or n generalised forces: the paper's idealised,
        unrealisable input) over ``steps`` RK4 steps.  ``tip_force`` (Fx, Fy) [N] in the
        base frame acts on the payload as generalised forces Jᵀ F, with the tip Jacobian
        J taken at the start of the period."""
        if tau.shape == (2,):
            self._tau[:] = tau
            tau_in = self._tau
        else:
            tau_in = np.ascontiguousarray(tau)
        f = self._f
        force = tip_force is not None and np.any(tip_force)
        f[:] = (self.model.tip_jacobian(self._x[:self.model.n]).T @ np.asarray(tip_force, float)
                if force else 0.0)
        ints, reals = self.model.packed
        wc, wr = self._work
        if self._joints_on:  # the motor torques go through the joints, Jᵀ F to the arm
            advance_joints_packed(ints, reals, wc, wr, self._x, tau_in, f, self.h, steps,
                                  *self._joints)
            return
        if force:
            f[:tau_in.shape[0]] += tau_in
            tau_in = f
        kern.rk4_advance_packed(ints, reals, wc, wr, self._x, tau_in, self.h, steps)

    def compiled_stepping(self) -> dict | None:
        """What a compiled loop needs to step this plant itself (`validation.run._sample.
        run_reduced`): the model's packed buffers, the live state, the step and the map
        to the measurement basis; None where this plant's Python path is needed — a
        measurement that is not the plain state (gauges, quantisation, payload position)."""
        cfg = self.sensors.config
        if cfg.strain_gauges is not None or cfg.encoder_resolution != 0 or cfg.tip_position:
            return None
        return {"model": (*self.model.packed, *self._work), "x": self._x, "h": self.h,
                "joints": self._joints,
                "basis": np.ascontiguousarray(self._readout, dtype=float),
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
        0, 0, motor angles and rates] written into ``out``."""
        n, x = self.model.n, self._x
        if self.model.links:
            m = 2 + self._readout.shape[0]
            out[:2], out[m:m + 2] = x[:2], x[n:n + 2]
            modal_readout_into(*self.model.packed, self._readout, x, out[2:m], out[m + 2:2 * m])
        elif self._basis_map is None:
            out[:2 * n] = x
        else:
            m = 2 + self._basis_map.shape[0]
            out[:2], out[m:m + 2] = x[:2], x[n:n + 2]
            out[2:m] = self._basis_map @ x[2:n]
            out[m + 2:2 * m] = self._basis_map @ x[n + 2:]
        kern.tip_kinematics_packed(*self.model.packed, x[:n], out[-12:-6])
        out[-6:-4] = 0.0  # the projection residual: not computed for the reduced plant
        motor_state_into(self._joints[0], self._joints[1], x, out[-4:])


def positive_step(step) -> None:
    """FieldError naming ``plant.step`` unless it is a positive number of seconds."""
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not (
            np.isfinite(step) and step > 0):
        raise FieldError("plant", "step", f"must be > 0, got {step!r}")
