"""The reduced model used as a plant: fixed-step RK4 on the paper's eq. (2), its joints,
and its truth vector — one compiled kernel (`reduced_step_linear` and its variants),
which its Python methods and compiled loops both call."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..arm import ArmParameters, FieldError
from ..contract import (PLANT_SIGNATURE, CompiledPlant, Plant, PlantSettings, SensorConfig,
                        kernel_pointer)
from ..dynamics import matrix_view, rk4_advance, tips_into, unpack_model, unpack_workspace
from ..joints import (advance_joints_exact, advance_joints_linear, joints_active,
                      motor_state_into, new_joint_buffers, reset_joints)
from ..joints.kernels import PARAMETERS
from ..model import ArmModel, cached_model, validate_kinematics, validate_modes_per_link
from ..shapes import projection, readout_matrix
from .linear import reduced_linear_model
from .readout import modal_readout_into

__all__ = ["ReducedPlant", "positive_step"]

# ``ints`` of the compiled form: internal steps per period, the readout's rows and
# columns, the laws' coordinates m (the truth vector is 2m + 6N long).
_STEPS, _ROWS, _COLS, _M = range(4)


@njit(cache=True, inline="always")
def _reduced_step(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth, exact, joints):
    """Advance (``advance``) over one control period, then write the truth vector: [θ, q,
    θ̇, q̇] in the laws' basis (the plant's readout), the tips, their deflections, zero
    projection residuals, the motors (`PLANT_SIGNATURE`)."""
    d = unpack_model(mi, mr)
    ws = unpack_workspace(mi, wc, wr)
    n, N = d.n, d.links
    x = state[:2 * n]
    js = state[2 * n:2 * n + 4 * N]
    jw = state[2 * n + 4 * N:]
    jp = reals[1:1 + len(PARAMETERS) * N]
    readout = matrix_view(reals, 1 + len(PARAMETERS) * N, ints[_ROWS], ints[_COLS])
    if advance:
        if joints:  # the motor torques go through the joints, ext to the arm
            if exact:
                advance_joints_exact(mi, mr, wc, wr, x, tau, ext, reals[0], ints[_STEPS], jp,
                                     js, jw)
            else:
                advance_joints_linear(mi, mr, wc, wr, x, tau, ext, reals[0], ints[_STEPS],
                                      jp, js, jw)
        else:
            rk4_advance(d, x, tau, reals[0], ints[_STEPS], ws, exact)
    m = ints[_M]
    for i in range(N):
        truth[i] = x[i]
        truth[m + i] = x[n + i]
    modal_readout_into(d, readout, x, truth[N:m], truth[m + N:2 * m], exact)
    o = 2 * m
    tips_into(d, x[:n], truth[o:o + 3 * N], exact)
    for i in range(N):
        truth[o + 3 * N + i] = 0.0  # the projection residual: none on the reduced plant
    motor_state_into(jp, js, x, truth[o + 4 * N:o + 6 * N])


@njit(cache=True)
def reduced_step_linear(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth):
    """`_reduced_step`: the paper's kinematics, ideal joints."""
    _reduced_step(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth, False, False)


@njit(cache=True)
def reduced_step_exact(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth):
    """`_reduced_step`: exact kinematics, ideal joints."""
    _reduced_step(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth, True, False)


@njit(cache=True)
def reduced_step_joints_linear(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth):
    """`_reduced_step`: the paper's kinematics, joint effects."""
    _reduced_step(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth, False, True)


@njit(cache=True)
def reduced_step_joints_exact(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth):
    """`_reduced_step`: exact kinematics, joint effects."""
    _reduced_step(advance, tau, ext, ints, reals, state, mi, mr, wc, wr, truth, True, True)


_KERNELS = {(False, False): reduced_step_linear, (True, False): reduced_step_exact,
            (False, True): reduced_step_joints_linear, (True, True): reduced_step_joints_exact}


class ReducedPlant(Plant):
    """`ArmModel` integrated with classical RK4 at a fixed internal step
    (``kind = "reduced"``: the paper's model as the plant).

    Torques are held constant over each control period (zero-order hold).  The
    measurement is set by ``sensors`` (default: encoders θ and the modal coordinates q
    read directly, as the paper assumes); noise belongs to the closed loop.  The joints
    of ``params`` (friction, drives, torque lag: `reduced_model.joints`) act as on the
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
    Ts : float
        The control period [s]: a whole multiple of ``step``.
    modes_per_link : sequence of int, optional
        Assumed modes per link of the plant model (1..4 each, 0 for a rigid link;
        default: the arm's).
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
    generalised_forces = True  # the idealised PBC's n forces, not only the joint torques

    @dataclass(frozen=True)
    class Settings(PlantSettings):
        """``kind = "reduced"``: the paper's model as the plant (fixed-step RK4).

        Parameters
        ----------
        kind : {"reduced"}
            Selects this plant.
        modes_per_link : list of int, optional
            The plant's own model order, assumed modes of each link (1..4; 0 for a rigid
            link; default: the arm's).
        step : float
            Internal RK4 step [s]; ``Ts`` must be a whole multiple of it.
        kinematics : {"linear", "exact"}
            How a link's points follow its modal deflection: the paper's linear
            kinematics, or the exact inextensible centreline (foreshortening included;
            the geometrically exact FE arm's, `reduced_model.ArmModel`).
        """

        kind: str = "reduced"
        modes_per_link: tuple[int, ...] | None = None
        step: float = 1e-3
        kinematics: str = "linear"

        def __post_init__(self):
            if self.kind != "reduced":
                raise FieldError("plant", "kind", f"must be 'reduced', got {self.kind!r}")
            if self.modes_per_link is not None:
                try:
                    object.__setattr__(self, "modes_per_link",
                                       validate_modes_per_link(self.modes_per_link))
                except ValueError:
                    raise FieldError("plant", "modes_per_link", "must be one integer in 0..4 "
                                     f"per link, got {self.modes_per_link!r}") from None
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
            own = cached_model(params, self.modes_per_link, self.kinematics)
            same = model.params == params and model.modes_per_link == own.modes_per_link
            return reduced_linear_model(own, theta=theta,
                                        modal_basis=None if same else model.mode_shapes)

    def __init__(self, params: ArmParameters | None = None, *, model: ArmModel | None = None,
                 sensors: SensorConfig = SensorConfig(), Ts: float = 1e-3,
                 modes_per_link=None, step: float = 1e-3, kinematics: str = "linear") -> None:
        params = params if params is not None else ArmParameters()
        self.model = cached_model(params, None if modes_per_link is None else
                                  validate_modes_per_link(modes_per_link, params),
                                  validate_kinematics(kinematics))
        n, N = self.model.n, self.model.n_joints
        own = model is None or (model.params == params
                                and model.modes_per_link == self.model.modes_per_link)
        basis = self.model.mode_shapes if own else model.mode_shapes
        self._basis_map = None if own else projection(self.model.mode_shapes, basis)
        #: The map to the measured q (`reduced_model.plant.readout`): the basis map, or the
        #: exact kinematics' readout of its centreline.
        readout = readout_matrix(self.model.links, basis) if self.model.exact else (
            np.zeros((0, 0)) if own else self._basis_map)
        jp, js, jw = new_joint_buffers(params, n)
        self._joints_on = joints_active(jp)
        self.encoder_side = tuple("motor" if j.has_drive else "link" for j in params.joints)
        Plant.__init__(self, sensors, basis, step, Ts)
        m = N + sum(b.n for b in basis)
        ints = np.zeros(4, dtype=np.int64)
        ints[_STEPS], ints[_ROWS], ints[_COLS], ints[_M] = self.steps, *readout.shape, m
        reals = np.concatenate([[self.h], jp, np.ravel(readout)])
        state = np.concatenate([np.zeros(2 * n), js, jw])
        kernel = _KERNELS[self.model.exact, self._joints_on]
        self._form = CompiledPlant(kernel_pointer(kernel, PLANT_SIGNATURE), ints, reals, state,
                                   *self.model.packed, *self.model.new_workspace())
        self._kernel = kernel
        self._x = state[:2 * n]  # views of the form's buffers: what a compiled run does
        self._js = state[2 * n:2 * n + 4 * N]
        self._jp = reals[1:1 + jp.size]
        self._truth = np.zeros(self.truth_size)
        self._tau = np.zeros(N)
        self._ext = np.zeros(n)  # generalised forces of a payload force

    def _call(self, advance: bool, tau: np.ndarray, ext: np.ndarray) -> None:
        f = self._form
        self._kernel(advance, tau, ext, f.ints, f.reals, f.state, f.model_ints, f.model_reals,
                     f.work_complex, f.work_real, self._truth)

    # --- sensor primitives (see reduced_model.contract.sensors) -----------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        n, N = self.model.n, self.n_joints
        return self._x[0:N].copy(), self._x[n:n + N].copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) in the modal basis (exact kinematics: of the centreline, as the FE
        plant reads its own, `reduced_model.plant.readout`)."""
        N = self.n_joints
        m = self._form.ints[_M]
        return self._truth[N:m].copy(), self._truth[m + N:2 * m].copy()

    def field_sampler(self, link: int, x, derivative: int):
        """Callable giving w_link^(derivative)(x) = Σ φ^(derivative)(x) q (modal field);
        with exact kinematics the centreline's transverse position (derivative 0) or its
        curvature (2)."""
        c = self.n_joints + sum(self.model.modes_per_link[:link])
        coords = slice(c, c + self.model.modes_per_link[link])
        if self.model.exact:
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
        reset_joints(self._jp, self._js, self._x)
        self._call(False, self._tau, self._ext)

    def _advance(self, tau: np.ndarray, tip_force) -> None:
        """Hold ``tau`` (N joint torques, or n generalised forces: the paper's idealised,
        unrealisable input) over one control period.  ``tip_force`` (Fx, Fy) [N] in the
        base frame acts on the payload as generalised forces Jᵀ F, with the tip Jacobian
        J taken at the start of the period."""
        if tau.shape == (self.n_joints,):
            self._tau[:] = tau
            tau_in = self._tau
        else:
            tau_in = np.ascontiguousarray(tau)
        f = self._ext
        force = tip_force is not None and np.any(tip_force)
        f[:] = (self.model.tip_jacobian(self._x[:self.model.n]).T @ np.asarray(tip_force, float)
                if force else 0.0)
        if not self._joints_on and force:
            f = f.copy()
            f[:tau_in.shape[0]] += tau_in
            tau_in = f
        self._call(True, tau_in, self._ext)

    def compiled(self) -> CompiledPlant:
        """Its compiled form (`reduced_model.contract.compiled`): the kernel of its
        kinematics and joints, on its own buffers."""
        return self._form

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
        0 …, motor angles and rates] written into ``out``."""
        out[:] = self._truth


def positive_step(step) -> None:
    """FieldError naming ``plant.step`` unless it is a positive number of seconds."""
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not (
            np.isfinite(step) and step > 0):
        raise FieldError("plant", "step", f"must be > 0, got {step!r}")
