"""The truth plant: the arm's Exudyn model stepped one control period at a time."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reduced_model import (LEVELS, ArmModel, ArmParameters, FieldError, Measurement,
                           Plant, PlantFailure, PlantSettings, Refinement, SensorConfig,
                           cached_model)
from reduced_model.arm import JOINT_EFFECTS, MAX_LINKS
from reduced_model.joints import lag_step, with_joints
from reduced_model.plant import positive_step

from ._mesh import MAX_ELEMENTS, Mesh, mesh_label

__all__ = ["ExudynPlant", "linear_model"]

#: Element-count ratio of the geometrically exact beam to ANCF in a check: it converges
#: slower (open-loop 4th-mode error: GE 16 el/link 0.6 %, ANCF 4 0.04 %).
_GE_PER_ANCF = 8
#: A number of steps no period reaches: a reduced step is not grown back (`_pre_step`).
_NEVER = 2**31 - 1
#: How far (in steps) Exudyn's time may pass a step boundary by round-off and still end
#: the step before it (`_pre_step`).
_ENDS = 1e-6


def _plain(elements_per_link):
    """A mesh's elements per link as a plant table holds it (a list, or one number)."""
    return elements_per_link if isinstance(elements_per_link, int) else list(elements_per_link)


class ExudynPlant(Plant):
    """A planar arm of 1–4 links as an Exudyn FE model (``kind = "exudyn"``: the truth
    plant; the plant contract: `reduced_model.Plant`): flexible links as ANCF cable
    elements (default) or geometrically exact beams, rigid links as rigid bodies, the
    joints' friction and drives, gravity (`plant_exudyn.build_arm`).

    Parameters
    ----------
    params : ArmParameters
        The true arm.
    model : ArmModel, optional
        The model whose mode shapes the deflection is projected on for `truth` and for
        measurements (the controller's nominal model); default: the reduced model of
        ``params`` with its modes per link.
    sensors : SensorConfig
        What `step` returns (default: encoders θ and the projected modal q).
    Ts : float
        The control period [s] each command is held for: a whole multiple of ``step``.
    step, mesh, spectral_radius, newton_tolerance
        Its settings (`ExudynPlant.Settings`).

    Coordinates: θ1 is hub 1's angle; θi is hub i's angle relative to the tangent of
    link i−1 at its tip (what a motor-i encoder reads).  q, q̇ are the mass-weighted
    projections of each flexible link's transverse deflection in its root frame
    (`LinkField`); a rigid link has none.  The arm starts where `reset` places it
    (undeformed by default, also in gravity: no static solve).  The solver is
    initialised once per `reset` and advanced period by period: identical to a
    continuous run.

    Attributes
    ----------
    hold : ExactHold or None
        How each period's loads are applied: an exact zero-order hold (`ExactHold`,
        second order in the step).  None gives Exudyn's own treatment of a load that
        jumps at a step boundary, first order in the step: the known-bad reference of
        the tests and benchmarks (`validation.run.replay.bare_replay`).
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
            The finite elements of the flexible links (`plant_exudyn.Mesh`).
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
            table["mesh"]["elements_per_link"] = _plain(self.mesh.refined(2 ** level))
            table["step"] = self.step / 2 ** level
            return table

        def refinements(self) -> list[Refinement]:
            """Level 1 and 2 of the same element (mesh and step refined together), then
            the other formulation at a resolution at least as fine with half the step (GE
            8× the ANCF elements; ANCF 1/8 of GE's); meshes beyond 64 el/link are left
            out."""
            tables = [(self.refined(level), f"step/{2 ** level}", level) for level in LEVELS]
            table = self.refined(1)
            if self.mesh.element == "ancf":
                table["mesh"].update(element="geometrically_exact",
                                     elements_per_link=_plain(self.mesh.refined(_GE_PER_ANCF)))
            else:
                epl = self.mesh.elements_per_link
                table["mesh"].update(element="ancf", elements_per_link=(
                    max(1, epl // _GE_PER_ANCF) if isinstance(epl, int)
                    else [max(1, k // _GE_PER_ANCF) for k in epl]))
            tables.append((table, "step/2", None))
            # left out before a Mesh is made of them: Mesh refuses more than 64 el/link
            return [Refinement(f"{mesh_label(Mesh(**t['mesh']))}, {step}", t, level)
                    for t, step, level in tables
                    if np.max(t["mesh"]["elements_per_link"]) <= MAX_ELEMENTS]

        def step_cost(self) -> float:
            """Pessimistic, measured on the paper's arm (one number of elements: counted
            for as many links as an arm has at most)."""
            epl = self.mesh.elements_per_link
            total = MAX_LINKS * epl if isinstance(epl, int) else sum(epl)
            return 2.5e-4 + 3e-5 * total

        def linear_model(self, params, *, theta, model):
            return linear_model(params, self.mesh, theta=theta, model=model)

    def __init__(self, params: ArmParameters | None = None, *, model: ArmModel | None = None,
                 sensors: SensorConfig = SensorConfig(), Ts: float = 1e-3, step: float = 5e-4,
                 mesh: Mesh = Mesh(), spectral_radius: float = 0.9,
                 newton_tolerance: float = 1e-6) -> None:
        import exudyn as exu  # the solver is loaded by the runs that use it

        from ._build import build_arm, simulation_settings
        from ._fields import LinkField
        from ._hold import ExactHold, scaled
        from ._readout import link_arrays, new_readout, readout_into
        if not 0.0 < spectral_radius <= 1.0:
            raise ValueError(f"spectral_radius must be in (0, 1], got {spectral_radius!r}")
        if not (np.isfinite(newton_tolerance) and newton_tolerance > 0):
            raise ValueError(f"newton_tolerance must be > 0, got {newton_tolerance!r}")
        self.params = p = params if params is not None else ArmParameters()
        self.mesh = mesh
        basis = (model or cached_model(p)).mode_shapes
        if len(basis) != p.n_links or any(m.n and link.rigid for m, link in zip(basis, p.links)):
            raise ValueError(f"the model's modes per link {tuple(m.n for m in basis)} do not "
                             f"fit the {p.n_links}-link arm with modes {p.modes()} (a rigid "
                             "link has none)")
        self._state_size = 2 * (p.n_links + sum(m.n for m in basis))  # read every sample
        self.system = build_arm(p, mesh, step=step)
        #: Each link's `LinkField` (None for a rigid link).
        self.fields = tuple(None if link.rigid else LinkField(self.system, i, basis[i])
                            for i, link in enumerate(p.links))
        self.encoder_side = tuple("motor" if j.has_drive else "link" for j in p.joints)
        Plant.__init__(self, sensors, basis, step, Ts)
        self.settings = simulation_settings(step=self.h, spectral_radius=spectral_radius,
                                            newton_tolerance=newton_tolerance)
        self.solver = exu.MainSolverImplicitSecondOrder()
        tip = self.system.tip_load
        self._inputs = self.system.joints.inputs  # the loads each τi sets (`_drives`)
        self._scaled = scaled
        self.hold = ExactHold(
            self.system.mbs, self.settings, self.h,
            [*self._inputs, [(tip, "loadVector", (1.0, 0.0, 0.0))],
             [(tip, "loadVector", (0.0, 1.0, 0.0))]],
            self.system.beam_nodes if self.system.element == "ancf" else [],
            [link.node for link in self.system.rigid_links],
            self.system.joints.sticks(self.system.mbs))
        N = p.n_links
        self._applied = np.zeros(N + 2)  # the loads held now: τ1 … τN, Fx, Fy
        #: The current loops' time constants and outputs (`reduced_model.joints.lag_step`).
        self._lag = np.array([j.torque_time_constant for j in p.joints])
        self._lagging = bool(self._lag.any())
        self._lagged = np.zeros(N)
        if self._lagging:  # the current loops' torques change every step: `_advance`
            #: Per step of the period being solved, the torques held (τ1 … τN).
            self._schedule = np.zeros((self.steps, N))
            self._held = 0  # the step of the period whose torques are held
            self._force = (0.0, 0.0)  # the period's payload force
            self.settings.timeIntegration.adaptiveStepRecoverySteps = _NEVER
            self.system.mbs.SetPreStepUserFunction(self._pre_step)
        self._read_motors = self.system.joints.motor_reader(self.system.mbs)
        self._readout = new_readout(self.system.element == "ancf", *readout_arrays(self.system),
                                    link_arrays(f for f in self.fields if f is not None))
        self._readout_into = readout_into
        self._truth = None
        self._cache = None  # state readout of the current step (see _read)
        self._initial = exu.ConfigurationType.Initial
        # Bound once: the loop advances and reads the plant every sample.
        self._set_load = self.system.mbs.SetLoadParameter
        self._iteration = self.solver.it
        self._system_data = self.system.mbs.systemData

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

    def _advance(self, tau: np.ndarray, tip_force) -> None:
        """Hold joint torques ``tau`` and the payload force ``tip_force`` over one control
        period (an exact zero-order hold, `hold_loads`); `PlantFailure` with Exudyn's
        message if the solver fails."""
        steps = self.steps
        fx, fy = (0.0, 0.0) if tip_force is None else (float(tip_force[0]),
                                                       float(tip_force[1]))
        self._cache = self._truth = None
        if not self._lagging:
            self.hold_loads([float(t) for t in tau], fx, fy)
            self._solve_to(self._steps + steps)
            return
        lagged, lag, h, schedule = self._lagged, self._lag, self.h, self._schedule
        N = len(lagged)
        for k in range(steps):  # the current loops' mean torque step by step
            for i in range(N):
                schedule[k, i], lagged[i] = lag_step(float(tau[i]), lagged[i], lag[i], h)
        self._held, self._force = 0, (fx, fy)
        self.hold_loads(schedule[0].tolist(), fx, fy)
        self._solve_to(self._steps + steps)  # `_pre_step` holds the later steps' torques

    def _pre_step(self, mbs, t: float) -> bool:
        """Exudyn's pre-step function with current loops: at the start of a control
        period's later steps, hold that step's torques (`_advance`) from the step's start,
        in the state Exudyn repeats a step from as well as in the current one.

        One `SolveSteps` per control period, as with ideal joints, rather than one per step:
        each call makes Exudyn's modified Newton compute and factorise a new Jacobian.  A
        reduced step (its end ``t`` within step k) never grows back within the period
        (``adaptiveStepRecoverySteps``), so no step straddles the boundary where the
        torques change."""
        k = min(math.ceil(t / self.h - self._steps - _ENDS), self.steps) - 1
        if k > self._held:
            self._held = k
            self.hold_loads(self._schedule[k].tolist(), *self._force, start_of_step=True)
        return True

    def _solve_to(self, step: int) -> None:
        """Advance Exudyn's solver to the end of internal step ``step``."""
        self._iteration.endTime = step * self.h
        if not self.solver.SolveSteps(self.system.mbs, self.settings):
            msg = self.solver.GetErrorString() or "Newton iteration did not converge"
            raise PlantFailure(f"Exudyn solver failed at t = {self._iteration.currentTime:.6g} "
                               f"s: {msg.strip()}")

    def hold_loads(self, torques, fx: float = 0.0, fy: float = 0.0, *,
                   start_of_step: bool = False) -> None:
        """Hold joint torques ``torques`` (N values) [N m] and the payload force (``fx``,
        ``fy``) [N] from now on: set the loads that changed and, with the exact hold,
        restart the next step from the accelerations they give (`ExactHold`).
        ``start_of_step``: called inside a solve, at a step's start (`ExactHold.apply`)."""
        new = [*torques, fx, fy]
        applied = self._applied
        if self.hold is not None and any(a != b for a, b in zip(new, applied)):
            self.hold.apply([a - b for a, b in zip(new, applied)], start_of_step=start_of_step)
        self.set_loads(new)

    def set_loads(self, new) -> None:
        """Set the loads of the inputs (τ1 … τN, Fx, Fy) ``new`` that changed (no hold)."""
        applied = self._applied
        set_load, scaled = self._set_load, self._scaled
        N = len(self._inputs)
        for j in range(N):
            if new[j] != applied[j]:
                for load, parameter, value in self._inputs[j]:
                    set_load(load, parameter, scaled(value, new[j]))
        if new[N] != applied[N] or new[N + 1] != applied[N + 1]:
            set_load(self.system.tip_load, "loadVector", [new[N], new[N + 1], 0.0])
        applied[:] = new

    def measure(self) -> Measurement:
        """The measurement now (the truth vector read once per step and shared)."""
        index = self.sensors.truth_index
        if index is not None:  # the measured values are part of the truth vector
            return Measurement(self.time, self.sensors.names, self._truth_now()[index])
        return self.sensors.measure(self.time)

    def truth_vector(self) -> np.ndarray:
        """[θ, q, θ̇, q̇ (projected), tip positions, tip deflections, projection residuals,
        motors]."""
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

    # --- sensor primitives (see reduced_model.contract.sensors) ----------------------------
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        truth, m, N = self._truth_now(), self._state_size // 2, self.n_joints
        return truth[:N].copy(), truth[m:m + N].copy()

    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        truth, m, N = self._truth_now(), self._state_size // 2, self.n_joints
        return truth[N:m].copy(), truth[m + N:2 * m].copy()

    def field_sampler(self, link: int, x, derivative: int):
        """Callable giving the ``derivative``-th s-derivative of link ``link``'s transverse
        deflection (root frame) at points ``x``, from the FE interpolation (0 on a rigid
        link)."""
        field = self.fields[link]
        if field is None:
            zeros = np.zeros(np.size(x))
            return lambda: zeros.copy()
        H = field.interpolation(x, derivative)
        return lambda: H @ self._local_dofs()[link]

    def tip_positions(self) -> np.ndarray:
        e, N = self._state_size, self.n_joints
        return self._truth_now()[e:e + 2 * N].reshape(N, 2).copy()

    def _local_dofs(self) -> list:
        """Each flexible link's local dofs now (`LinkField.local_dofs`; None for a rigid
        link), read once per step (treat as read-only)."""
        if self._cache is None:
            sd = self._system_data
            u = sd.GetODE2Coordinates()
            self._cache = [None if f is None else f.local_dofs(u).copy() for f in self.fields]
        return self._cache

    def _node_displacements(self, Q: np.ndarray) -> np.ndarray:
        """ODE2 displacement vector placing every node for the configuration Q = [θ, q]
        (`_placement.node_displacements`)."""
        from ._placement import node_displacements
        return node_displacements(self.system, self.modal_basis, Q)

    # --- modal analysis ---------------------------------------------------------------------------
    def natural_frequencies(self, theta=None, joints: str = "locked",
                            n: int = 4) -> np.ndarray:
        """First ``n`` bending frequencies [Hz] of this plant's FE model linearised at
        ``theta`` (see `plant_exudyn.natural_frequencies`)."""
        from ._modal import natural_frequencies
        return natural_frequencies(self.params, self.mesh, theta=theta, joints=joints, n=n)


def readout_arrays(system) -> tuple:
    """The joints' and tips' indices and reference values `new_readout` reads from, for
    the `ArmSystem` ``system`` (`_readout.new_readout` says what each is)."""
    from ._bodies import LinkNodes
    from ._readout import ROTATION, SLOPE
    mbs = system.mbs
    ltg = mbs.systemData.GetNodeLTGODE2
    ref = lambda n: np.array(mbs.GetNodeParameter(n, "referenceCoordinates"), float)  # noqa
    N = len(system.links)
    ancf = system.element == "ancf"
    hub_idx = np.array([ltg(h)[2] for h in system.hubs], dtype=np.int64)
    hub_ref = np.array([ref(h)[2] for h in system.hubs])
    kind = np.zeros(N, dtype=np.int64)
    t_idx, t_ref = np.zeros((N, 2), dtype=np.int64), np.zeros((N, 2))
    tip_idx, tip_ref, tip_arm = np.full((N, 3), -1, dtype=np.int64), np.zeros((N, 2)), np.zeros((N, 2))
    field_of = np.full(N, -1, dtype=np.int64)
    fields = 0
    for i, link in enumerate(system.links):
        if isinstance(link, LinkNodes):
            node = link.nodes[-1]
            field_of[i], fields = fields, fields + 1
            tip_idx[i, :2], tip_ref[i] = ltg(node)[:2], ref(node)[:2]
            slope = (SLOPE, ltg(node)[2:4], ref(node)[2:4]) if ancf else (
                ROTATION, [ltg(node)[2], 0], [ref(node)[2], 0.0])
        else:
            node, angle = link.node, ref(link.node)[2]
            tip_idx[i], tip_ref[i] = ltg(node), ref(node)[:2]
            tip_arm[i] = (link.length - link.centre) * np.array([np.cos(angle), np.sin(angle)])
            slope = (ROTATION, [ltg(node)[2], 0], [angle, 0.0])
        if i + 1 < N:
            kind[i + 1], t_idx[i + 1], t_ref[i + 1] = slope
    return hub_idx, hub_ref, kind, t_idx, t_ref, tip_idx, tip_ref, tip_arm, field_of


def linear_model(params: ArmParameters | None = None, mesh: Mesh = Mesh(), *,
                 theta=None, Ts: float | None = None,
                 model: ArmModel | None = None):
    """The FE arm linearised about rest at joint angles ``theta`` (`plant_exudyn._linear`).

    Parameters
    ----------
    params : ArmParameters
        The arm, horizontal (default: `ArmParameters()`).
    mesh : Mesh
        Element type and elements per flexible link.
    theta : sequence of float, optional
        θ1 … θN [rad] of the configuration (θi relative to link i−1's tip tangent;
        default 0).
    Ts : float, optional
        If given, the exact zero-order-hold discretisation at this period [s].
    model : ArmModel, optional
        The model whose mode shapes the deflection is projected on for the q outputs
        (default: the reduced model of ``params`` with its modes per link, as `ExudynPlant`).

    Returns
    -------
    control.StateSpace
        Inputs ``tau1`` … ``tauN`` [N m]; outputs `reduced_model.output_names`
        (deviations from the configuration: rad, m, rad/s, m/s); states ``eta1…`` (FE
        modes, the first N rigid) and their rates, then the drives' and current loops'
        (the linear part of the arm's joints, `reduced_model.joints.with_joints`; dry
        friction and backlash are left out).  Continuous, or discrete with ``dt = Ts``.
    """
    import control

    from ._linear import linearise
    params = params if params is not None else ArmParameters()
    arm = linearise(ExudynPlant(params.without(*JOINT_EFFECTS), model=model, mesh=mesh),
                    theta=theta)
    sys_ = with_joints(arm, params)
    return sys_ if Ts is None else control.sample_system(sys_, Ts, method="zoh",
                                                         name=sys_.name + "_zoh")
