"""The truth plant: the arm's Exudyn model stepped one control period at a time."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reduced_model import (ArmModel, ArmParameters, FieldError, LinkModes, Measurement,
                           Plant, PlantFailure, SensorConfig, cached_model)
from reduced_model._joint_linear import with_joints
from reduced_model._joints import lag_step
from reduced_model._parameters import JOINT_EFFECTS
from reduced_model._plant import positive_step
from reduced_model._plant_base import LEVELS, PlantSettings, Refinement

from ._mesh import Mesh, mesh_label

__all__ = ["ExudynPlant", "linear_model"]

#: Element-count ratio of the geometrically exact beam to ANCF in a check: it converges
#: slower (open-loop 4th-mode error: GE 16 el/link 0.6 %, ANCF 4 0.04 %).
_GE_PER_ANCF = 8
_MAX_ELEMENTS = 64


class ExudynPlant(Plant):
    """Two-link flexible arm as an Exudyn FE model (``kind = "exudyn"``: the truth plant;
    the plant contract: `reduced_model.Plant`).

    Parameters
    ----------
    params : ArmParameters
        The true arm.
    model : ArmModel, optional
        The model whose mode shapes the deflection is projected on for `truth` and for
        measurements (the controller's nominal model); default: the reduced model of
        ``params`` with 2 modes per link.
    sensors : SensorConfig
        What `step` returns (default: encoders θ and the projected modal q).
    step, mesh, spectral_radius, newton_tolerance
        Its settings (`ExudynPlant.Settings`).
    exact_hold : bool
        Apply each period's loads as an exact zero-order hold (default; `ExactHold`:
        second order in the step).  False gives Exudyn's own treatment of a load that
        jumps at a step boundary, first order in the step: kept as the known-bad
        reference of the tests and benchmarks.

    Coordinates: θ1 is hub 1's angle; θ2 is hub 2's angle relative to the tangent of
    link 1 at its tip (what a motor-2 encoder reads).  q, q̇ are the mass-weighted
    projections of each link's transverse deflection in its root frame (`LinkField`).
    The solver is initialised once per `reset` and advanced period by period: identical
    to a continuous run.
    """

    role = "truth"
    label = "truth plant (Exudyn)"

    @dataclass(frozen=True)
    class Settings(PlantSettings):
        """``kind = "exudyn"``: the FE truth plant.

        The default step, 0.5 ms, is half the campaigns' 1 ms period: a sign observer's
        chatter drives the FE arm at the Nyquist frequency, where a 1 ms step moved a 5 s
        PBC + sign-SMO run's tracking error by 40 % (0.0138 rad against 0.0094-0.0111 on
        finer meshes and steps).

        Parameters
        ----------
        kind : {"exudyn"}
            Selects this plant.
        step : float
            Generalised-α integration step [s]; ``Ts`` must be a whole multiple of it.
        mesh : Mesh
            The finite elements of both links (`plant_exudyn.Mesh`).
        spectral_radius : float
            Generalised-α ρ∞ (1: no numerical damping; the default 0.9 damps only modes
            far above 1/step).
        newton_tolerance : float
            Absolute and relative tolerance of Exudyn's Newton iterations (ANCF round-off
            makes much smaller absolute tolerances unreachable: the solver then fails).
        """

        kind: str = "exudyn"
        step: float = 5e-4
        mesh: Mesh = Mesh()
        spectral_radius: float = 0.9
        newton_tolerance: float = 1e-6

        def __post_init__(self):
            if self.kind != "exudyn":
                raise FieldError("plant", "kind", f"must be 'exudyn', got {self.kind!r}")
            positive_step(self.step)
            tol = self.newton_tolerance
            if not (np.isfinite(tol) and tol > 0):
                raise FieldError("plant", "newton_tolerance", f"must be > 0, got {tol!r}")
            if not 0 < self.spectral_radius <= 1:
                raise FieldError("plant", "spectral_radius", "must be in (0, 1] (the exact "
                                 "zero-order hold needs alpha_f > 0), got "
                                 f"{self.spectral_radius!r}")

        def discretisation(self) -> str:
            return mesh_label(self.mesh)

        def refined(self, level: int) -> dict:
            table = self.table()
            table["mesh"]["elements_per_link"] = [2 ** level * n for n in
                                                  self.mesh.elements_per_link]
            table["step"] = self.step / 2 ** level
            return table

        def refinements(self) -> list[Refinement]:
            """Level 1 and 2 of the same element (mesh and step refined together), then
            the other formulation at a resolution at least as fine with half the step (GE
            8× the ANCF elements; ANCF 1/8 of GE's); meshes beyond 64 el/link are left
            out."""
            tables = [(self.refined(level), f"step/{2 ** level}", level) for level in LEVELS]
            n = self.mesh.elements_per_link
            table = self.refined(1)
            if self.mesh.element == "ancf":
                table["mesh"].update(element="geometrically_exact",
                                     elements_per_link=[_GE_PER_ANCF * k for k in n])
            else:
                table["mesh"].update(element="ancf",
                                     elements_per_link=[max(1, k // _GE_PER_ANCF) for k in n])
            tables.append((table, "step/2", None))
            # left out before a Mesh is made of them: Mesh refuses more than 64 el/link
            return [Refinement(f"{mesh_label(Mesh(**t['mesh']))}, {step}", t, level)
                    for t, step, level in tables
                    if max(t["mesh"]["elements_per_link"]) <= _MAX_ELEMENTS]

        def step_cost(self) -> float:
            return 2.5e-4 + 3e-5 * sum(self.mesh.elements_per_link)  # pessimistic, measured

        def linear_model(self, params, *, theta, model):
            return linear_model(params, self.mesh, theta=theta, model=model)

    def __init__(self, params: ArmParameters | None = None, *, model: ArmModel | None = None,
                 sensors: SensorConfig = SensorConfig(), step: float = 5e-4,
                 mesh: Mesh = Mesh(), spectral_radius: float = 0.9,
                 newton_tolerance: float = 1e-6, exact_hold: bool = True) -> None:
        import exudyn as exu  # the solver is loaded by the runs that use it

        from ._build import build_arm, simulation_settings
        from ._fields import LinkField
        from ._hold import ExactHold, scaled
        from ._readout import new_readout, readout_into
        if not 0.0 < spectral_radius <= 1.0:
            raise ValueError(f"spectral_radius must be in (0, 1], got {spectral_radius!r}")
        if not (np.isfinite(newton_tolerance) and newton_tolerance > 0):
            raise ValueError(f"newton_tolerance must be > 0, got {newton_tolerance!r}")
        self.params = params if params is not None else ArmParameters()
        self.mesh = mesh
        basis = (model or cached_model(self.params, (2, 2))).mode_shapes
        self.modal_basis = basis
        self._state_size = 2 * (2 + sum(m.n for m in basis))  # read every sample
        self.system = build_arm(self.params, mesh, step=step)
        self.fields = (LinkField(self.system, 0, basis[0]), LinkField(self.system, 1, basis[1]))
        p = self.params
        self.encoder_side = tuple("motor" if p.has_drive(i) else "link" for i in (1, 2))
        Plant.__init__(self, sensors, basis, step)
        self.settings = simulation_settings(step=self.h, spectral_radius=spectral_radius,
                                            newton_tolerance=newton_tolerance)
        self.solver = exu.MainSolverImplicitSecondOrder()
        tip = self.system.tip_load
        self._inputs = self.system.joints.inputs  # the loads τ1 and τ2 set (`_drives`)
        self._scaled = scaled
        self.hold = ExactHold(
            self.system.mbs, self.settings, self.h,
            [*self._inputs, [(tip, "loadVector", (1.0, 0.0, 0.0))],
             [(tip, "loadVector", (0.0, 1.0, 0.0))]],
            [n for link in self.system.links for n in link.nodes]
            if self.system.element == "ancf" else [],
            self.system.joints.sticks(self.system.mbs)) if exact_hold else None
        self._applied = np.zeros(4)  # the loads held now: τ1, τ2, Fx, Fy
        #: The current loops' time constants and outputs (`reduced_model._joints.lag_step`).
        self._lag = np.array([p.torque_time_constant1, p.torque_time_constant2])
        self._lagging = bool(self._lag.any())
        self._lagged = np.zeros(2)
        self._read_motors = self.system.joints.motor_reader(self.system.mbs)
        self._index_state()
        self._readout = new_readout(self.system.element == "ancf", *self._joint_arrays(),
                                    *self.fields[0].compiled(), *self.fields[1].compiled())
        self._readout_into = readout_into
        self._truth = None
        self._cache = None  # state readout of the current step (see _read)
        self._initial = exu.ConfigurationType.Initial
        # Bound once: the loop advances and reads the plant every sample.
        self._set_load = self.system.mbs.SetLoadParameter
        self._iteration = self.solver.it
        self._system_data = self.system.mbs.systemData

    def _index_state(self) -> None:
        """Cache ODE2 indices and reference values of everything `truth` reads."""
        mbs, sys_ = self.system.mbs, self.system
        ltg = mbs.systemData.GetNodeLTGODE2
        ref = lambda n: np.array(mbs.GetNodeParameter(n, "referenceCoordinates"), float)  # noqa
        self._hub1_rot, self._hub2_rot = ltg(sys_.hub1)[2], ltg(sys_.hub2)[2]
        self._hub1_ref, self._hub2_ref = ref(sys_.hub1)[2], ref(sys_.hub2)[2]
        tip1, tip2 = sys_.links[0].nodes[-1], sys_.links[1].nodes[-1]
        self._tip_idx = np.array([ltg(tip1)[:2], ltg(tip2)[:2]])
        self._tip_ref = np.array([ref(tip1)[:2], ref(tip2)[:2]])
        if sys_.element == "ancf":
            self._tip1_slope_idx = np.array(ltg(tip1)[2:4])
            self._tip1_slope_ref = ref(tip1)[2:4]
        else:
            self._tip1_rot_idx, self._tip1_rot_ref = ltg(tip1)[2], ref(tip1)[2]

    # --- Plant interface ---------------------------------------------------------------
    @property
    def state_size(self) -> int:
        """Length of [θ, q, θ̇, q̇] with q in the modal basis (what `reset` takes)."""
        return self._state_size

    def _reset(self, x0: np.ndarray) -> None:
        """Place the FE nodes on the inextensible curve of ``x0``'s modal deflection (q in
        the modal basis) and restart the solver there."""
        n = self.state_size // 2
        u = self._node_displacements(x0[:n])
        eps = 1e-6  # central difference along the velocity: exact for the linear part
        v = (self._node_displacements(x0[:n] + eps * x0[n:])
             - self._node_displacements(x0[:n] - eps * x0[n:])) / (2 * eps)
        sd = self.system.mbs.systemData
        sd.SetODE2Coordinates(u, configuration=self._initial)
        sd.SetODE2Coordinates_t(v, configuration=self._initial)
        if sd.DataSize():
            sd.SetDataCoordinates(self.system.joints.initial_data(self.system.mbs, u, v),
                                  configuration=self._initial)
        for load, parameter, value in (*(part for parts in self._inputs for part in parts),
                                       (self.system.tip_load, "loadVector", (0.0, 0.0, 0.0))):
            self.system.mbs.SetLoadParameter(load, parameter, self._scaled(value, 0.0))
        self._applied[:] = 0.0
        self._lagged[:] = 0.0
        self.settings.timeIntegration.startTime = 0.0
        if not self.solver.InitializeSolver(self.system.mbs, self.settings):
            raise PlantFailure(f"Exudyn could not initialise the solver: "
                               f"{self.solver.GetErrorString()}")
        self._cache = self._truth = None

    def _advance(self, tau: np.ndarray, steps: int, tip_force) -> None:
        """Hold joint torques ``tau`` and the payload force ``tip_force`` over ``steps``
        steps (an exact zero-order hold, `hold_loads`); `PlantFailure` with Exudyn's
        message if the solver fails."""
        fx, fy = (0.0, 0.0) if tip_force is None else (float(tip_force[0]),
                                                       float(tip_force[1]))
        self._cache = self._truth = None
        if not self._lagging:
            self.hold_loads(float(tau[0]), float(tau[1]), fx, fy)
            self._solve_to(self._steps + steps)
            return
        lagged = self._lagged
        for k in range(steps):  # the current loops' mean torque step by step
            (u1, lagged[0]), (u2, lagged[1]) = (lag_step(float(tau[i]), lagged[i], self._lag[i],
                                                         self.h) for i in (0, 1))
            self.hold_loads(u1, u2, fx, fy)
            self._solve_to(self._steps + k + 1)

    def _solve_to(self, step: int) -> None:
        """Advance Exudyn's solver to the end of internal step ``step``."""
        self._iteration.endTime = step * self.h
        if not self.solver.SolveSteps(self.system.mbs, self.settings):
            msg = self.solver.GetErrorString() or "Newton iteration did not converge"
            raise PlantFailure(f"Exudyn solver failed at t = {self._iteration.currentTime:.6g} "
                               f"s: {msg.strip()}")

    def hold_loads(self, t1: float, t2: float, fx: float = 0.0, fy: float = 0.0) -> None:
        """Hold joint torques ``t1``, ``t2`` [N m] and the payload force (``fx``, ``fy``)
        [N] from now on: set the loads that changed and, with the exact hold, restart the
        next step from the accelerations they give (`ExactHold`)."""
        new = (t1, t2, fx, fy)
        applied = self._applied
        if self.hold is not None and (new[0] != applied[0] or new[1] != applied[1]
                                      or new[2] != applied[2] or new[3] != applied[3]):
            self.hold.apply((new[0] - applied[0], new[1] - applied[1],
                             new[2] - applied[2], new[3] - applied[3]))
        self.set_loads(new)

    def set_loads(self, new) -> None:
        """Set the loads of the inputs (τ1, τ2, Fx, Fy) ``new`` that changed (no hold)."""
        applied = self._applied
        set_load, scaled = self._set_load, self._scaled
        for j in (0, 1):
            if new[j] != applied[j]:
                for load, parameter, value in self._inputs[j]:
                    set_load(load, parameter, scaled(value, new[j]))
        if new[2] != applied[2] or new[3] != applied[3]:
            set_load(self.system.tip_load, "loadVector", [new[2], new[3], 0.0])
        applied[:] = new

    def measure(self) -> Measurement:
        """The measurement now (the truth vector read once per step and shared)."""
        index = self.sensors.truth_index
        if index is not None:  # the measured values are part of the truth vector
            return Measurement(self.time, self.sensors.names, self._truth_now()[index])
        return self.sensors.measure(self.time)

    def truth_vector(self) -> np.ndarray:
        """[θ, q, θ̇, q̇ (projected), tip positions, tip deflections, projection residuals]."""
        return self._truth_now().copy()

    def truth_into(self, out: np.ndarray) -> None:
        """`truth_vector` written into ``out`` (one compiled call on Exudyn's coordinates,
        then the motors)."""
        sd = self._system_data
        u, v = sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t()
        self._readout_into(self._readout, u, v, out)
        self._read_motors(u, v, out, self._state_size // 2)

    def _truth_now(self) -> np.ndarray:
        """The truth vector of the current step, read once (treat as read-only)."""
        if self._truth is None:
            self._truth = np.empty(self.truth_size)
            self.truth_into(self._truth)
        return self._truth

    # --- sensor primitives (see reduced_model._sensors) -------------------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        _, theta, theta_dot, *_ = self._read()
        return theta.copy(), theta_dot.copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        *_, q, q_dot, _ = self._read()
        return q.copy(), q_dot.copy()

    def field_sampler(self, link: int, x, derivative: int):
        """Callable giving the ``derivative``-th s-derivative of link ``link``'s transverse
        deflection (root frame) at points ``x``, from the FE interpolation."""
        H = self.fields[link].interpolation(x, derivative)
        return lambda: H @ self._read()[5][link]

    def tip_positions(self) -> np.ndarray:
        return self._tip_positions(self._read()[0])

    # --- state reading ---------------------------------------------------------------------
    def _read(self):
        """(u, θ, θ̇, q, q̇, local dofs per link) of the current state, computed once per
        step and shared by the measurement and `truth` (treat as read-only)."""
        if self._cache is None:
            sd = self.system.mbs.systemData
            u, v = sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t()
            theta, theta_dot = self._joints(u, v)
            q, q_dot, dofs = [], [], []
            for f in self.fields:
                d, dd = f.local_dofs(u, v)
                dofs.append(d.copy())  # the field reuses its buffers on the next call
                q.append(f.project(d))
                q_dot.append(f.project(dd))
            self._cache = (u, theta, theta_dot, np.concatenate(q), np.concatenate(q_dot), dofs)
        return self._cache

    def _joint_arrays(self) -> tuple:
        """Indices and reference values `readout_into` reads the joints and tips from."""
        ancf = self.system.element == "ancf"
        slope = self._tip1_slope_idx if ancf else np.array([self._tip1_rot_idx, 0])
        slope_ref = self._tip1_slope_ref if ancf else np.array([self._tip1_rot_ref, 0.0])
        idx = np.array([self._hub1_rot, self._hub2_rot, *slope], dtype=np.int64)
        ref = np.array([self._hub1_ref, self._hub2_ref, *slope_ref], dtype=float)
        return (idx, ref, np.ascontiguousarray(self._tip_idx, dtype=np.int64),
                np.ascontiguousarray(self._tip_ref, dtype=float))

    def _tip_positions(self, u: np.ndarray) -> np.ndarray:
        return self._tip_ref + u[self._tip_idx]

    def _joints(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        th1 = self._hub1_ref + u[self._hub1_rot]
        hub2 = self._hub2_ref + u[self._hub2_rot]
        if self.system.element == "ancf":
            sx, sy = self._tip1_slope_ref + u[self._tip1_slope_idx]
            sxd, syd = v[self._tip1_slope_idx]
            c, s = np.cos(th1), np.sin(th1)
            # Tangent angle = θ1 + (small) angle of the slope in hub 1's frame: continuous.
            tangent = th1 + np.arctan2(-s * sx + c * sy, c * sx + s * sy)
            tangent_rate = (sx * syd - sy * sxd) / (sx * sx + sy * sy)
        else:
            tangent = self._tip1_rot_ref + u[self._tip1_rot_idx]
            tangent_rate = v[self._tip1_rot_idx]
        th1d = v[self._hub1_rot]
        return (np.array([th1, hub2 - tangent]),
                np.array([th1d, v[self._hub2_rot] - tangent_rate]))

    # --- initial conditions ------------------------------------------------------------------
    def _node_displacements(self, Q: np.ndarray) -> np.ndarray:
        """ODE2 displacement vector placing every node for the configuration Q = [θ, q]."""
        sys_, mbs = self.system, self.system.mbs
        n1 = self.modal_basis[0].n
        th1, th2, q1, q2 = Q[0], Q[1], Q[2:2 + n1], Q[2 + n1:]
        u = np.zeros(mbs.systemData.ODE2Size())

        def place(node, pos, angle_or_slope):
            idx = mbs.systemData.GetNodeLTGODE2(node)
            ref = np.array(mbs.GetNodeParameter(node, "referenceCoordinates"), float)
            u[idx] = np.concatenate([pos, np.atleast_1d(angle_or_slope)]) - ref

        def curve(modes: LinkModes, q, s):
            """Inextensible curve with slope angle β = atan(w'): (x, y, β) at arc lengths s."""
            fine = np.linspace(0.0, modes.L, 4001)
            beta = np.arctan(modes.dphi(fine).T @ q)
            from scipy.integrate import cumulative_trapezoid  # 0.2 s: not for a report
            x = cumulative_trapezoid(np.cos(beta), fine, initial=0.0)
            y = cumulative_trapezoid(np.sin(beta), fine, initial=0.0)
            return (np.interp(s, fine, x), np.interp(s, fine, y),
                    np.arctan(modes.dphi(s).T @ q))

        def place_link(link, origin, frame_angle, q):
            nodes = sys_.links[link]
            x, y, beta = curve(self.modal_basis[link], q, nodes.s)
            c, s = np.cos(frame_angle), np.sin(frame_angle)
            pos = origin + np.column_stack([c * x - s * y, s * x + c * y])
            for k, node in enumerate(nodes.nodes):
                ang = frame_angle + beta[k]
                if sys_.element == "ancf":
                    place(node, pos[k], [np.cos(ang), np.sin(ang)])
                else:
                    place(node, pos[k], ang)
            return pos[-1], frame_angle + beta[-1]

        place(sys_.hub1, [0.0, 0.0], th1)
        tip1, tangent1 = place_link(0, np.zeros(2), th1, q1)
        alpha = tangent1 + th2
        place(sys_.hub2, tip1, alpha)
        tip2, tangent2 = place_link(1, tip1, alpha, q2)
        if sys_.stator is not None:
            place(sys_.stator, tip1, tangent1)
        if sys_.payload is not None:
            place(sys_.payload, tip2, tangent2)
        for rotor, hub_angle in zip(sys_.joints.rotors, (th1, alpha)):
            if rotor is not None:  # on its hub: the gear unloaded
                u[mbs.systemData.GetNodeLTGODE2(rotor)[0]] = hub_angle - mbs.GetNodeParameter(
                    rotor, "referenceCoordinates")[0]
        return u

    # --- modal analysis ---------------------------------------------------------------------------
    def natural_frequencies(self, theta=(0.0, 0.0), joints: str = "locked",
                            n: int = 4) -> np.ndarray:
        """First ``n`` bending frequencies [Hz] of this plant's FE model linearised at
        ``theta`` (see `plant_exudyn.natural_frequencies`)."""
        from ._modal import natural_frequencies
        return natural_frequencies(self.params, self.mesh, theta=theta, joints=joints, n=n)


def linear_model(params: ArmParameters | None = None, mesh: Mesh = Mesh(), *,
                 theta=(0.0, 0.0), Ts: float | None = None,
                 model: ArmModel | None = None):
    """The FE arm linearised about rest at joint angles ``theta`` (`plant_exudyn._linear`).

    Parameters
    ----------
    params : ArmParameters
        The arm (default: `ArmParameters()`).
    mesh : Mesh
        Element type and elements per link.
    theta : (float, float)
        θ1, θ2 [rad] of the configuration (θ2 relative to the link-1 tip tangent).
    Ts : float, optional
        If given, the exact zero-order-hold discretisation at this period [s].
    model : ArmModel, optional
        The model whose mode shapes the deflection is projected on for the q outputs
        (default: the reduced model of ``params`` with 2 modes per link, as `ExudynPlant`).

    Returns
    -------
    control.StateSpace
        Inputs ``tau1``, ``tau2`` [N m]; outputs `reduced_model.output_names` (deviations
        from the configuration: rad, m, rad/s, m/s); states ``eta1…`` (FE modes, the first
        two rigid) and their rates, then the drives' and current loops' (the linear part
        of the arm's joints, `reduced_model._joint_linear.with_joints`; dry friction and
        backlash are left out).  Continuous, or discrete with ``dt = Ts``.
    """
    import control

    from ._linear import linearise
    params = params if params is not None else ArmParameters()
    arm = linearise(ExudynPlant(params.without(*JOINT_EFFECTS), model=model, mesh=mesh),
                    theta=theta)
    sys_ = with_joints(arm, params)
    return sys_ if Ts is None else control.sample_system(sys_, Ts, method="zoh",
                                                         name=sys_.name + "_zoh")
