"""The truth plant: the arm's Exudyn model stepped one control period at a time."""
from __future__ import annotations

import exudyn as exu
import numpy as np
from numba import njit, types
from numba.experimental import structref
from scipy.integrate import cumulative_trapezoid

from reduced_model import (ArmParameters, LinkModes, Measurement, Plant, PlantFailure,
                           SensorConfig, cached_model)

from ._build import ArmSystem, Mesh, build_arm
from ._fields import LinkField, link_readout
from ._hold import ExactHold
from ._modal import natural_frequencies

__all__ = ["ExudynPlant", "simulation_settings"]


def simulation_settings(*, step: float, spectral_radius: float = 0.9,
                        newton_tolerance: float = 1e-6) -> exu.SimulationSettings:
    """Generalised-α settings measured on this model (README, *The truth plant*): Newton tolerances
    1e-6 (the default absolute 1e-10 is below ANCF round-off), sparse linear solver
    reusing its analysed pattern, no solution file, no console output, fixed step ``step``, halved on Newton failure
    down to step/1000 (ten halvings; Exudyn's default 1e-8 s makes a hopeless step take
    seconds to be declared failed)."""
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.endTime = step
    ti.numberOfSteps = 1
    ti.startTime = 0.0
    ti.verboseMode = 0
    ti.automaticStepSize = False
    ti.minimumStepSize = step * 1e-3
    ti.newton.absoluteTolerance = newton_tolerance
    ti.newton.relativeTolerance = newton_tolerance
    ti.generalizedAlpha.spectralRadius = spectral_radius
    ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    ss.linearSolver.reuseAnalyzedPattern = True  # the sparsity never changes: identical results
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = 1e30
    ss.show.computationTime = False
    ss.show.statistics = False
    return ss


class ExudynPlant(Plant):
    """Two-link flexible arm as an Exudyn FE model (the plant contract: `reduced_model.Plant`).

    Parameters
    ----------
    params : ArmParameters
        The true arm.
    mesh : Mesh
        Beam element type and elements per link (default: ANCF, 4 per link).
    step : float
        Time step [s] of the generalised-α integrator (default 0.5 ms; each control period
        must be a whole number of steps).  The solver is initialised once per `reset`
        and advanced period by period: identical to a continuous run.
    modal_basis : (LinkModes, LinkModes), optional
        Mode shapes the deflection is projected on for `truth` and for measurements;
        default: the reduced model of ``params`` with 2 modes per link.
    sensors : SensorConfig
        What `step` returns (default: encoders θ and the projected modal q).
    spectral_radius : float
        Generalised-α ρ∞ (1: no numerical damping; the default 0.9 damps only modes far
        above 1/step).
    newton_tolerance : float
        Absolute and relative Newton tolerance (default 1e-6; ANCF round-off makes much
        smaller absolute tolerances unreachable: the solver then fails).
    exact_hold : bool
        Apply each period's loads as an exact zero-order hold (default; `ExactHold`:
        second order in the step).  False gives Exudyn's own treatment of a load that
        jumps at a step boundary, first order in the step: kept as the known-bad
        reference of the tests and benchmarks.

    Coordinates: θ1 is hub 1's angle; θ2 is hub 2's angle relative to the tangent of
    link 1 at its tip (what a motor-2 encoder reads).  q, q̇ are the mass-weighted
    projections of each link's transverse deflection in its root frame (`LinkField`).
    """

    name = "exudyn"
    role = "truth"

    def __init__(self, params: ArmParameters | None = None, mesh: Mesh = Mesh(), *,
                 step: float = 5e-4, modal_basis: tuple[LinkModes, LinkModes] | None = None,
                 sensors: SensorConfig = SensorConfig(), spectral_radius: float = 0.9,
                 newton_tolerance: float = 1e-6, exact_hold: bool = True) -> None:
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"step must be a positive number of seconds, got {step!r}")
        if not 0.0 < spectral_radius <= 1.0:
            raise ValueError(f"spectral_radius must be in (0, 1], got {spectral_radius!r}")
        self.params = params if params is not None else ArmParameters()
        self.mesh = mesh
        self.h = float(step)
        basis = tuple(modal_basis or cached_model(self.params, (2, 2)).mode_shapes)
        self.modal_basis = basis
        self.system: ArmSystem = build_arm(self.params, mesh)
        self.fields = (LinkField(self.system, 0, basis[0]), LinkField(self.system, 1, basis[1]))
        if not (np.isfinite(newton_tolerance) and newton_tolerance > 0):
            raise ValueError(f"newton_tolerance must be > 0, got {newton_tolerance!r}")
        self.settings = simulation_settings(step=self.h, spectral_radius=spectral_radius,
                                            newton_tolerance=newton_tolerance)
        self.solver = exu.MainSolverImplicitSecondOrder()
        l1, l2, l2r = self.system.loads
        tip = self.system.tip_load
        self.hold = ExactHold(
            self.system.mbs, self.settings, self.h,
            [[(l1, (0, 0, 1))], [(l2, (0, 0, 1)), (l2r, (0, 0, -1))], [(tip, (1, 0, 0))],
             [(tip, (0, 1, 0))]],
            [n for link in self.system.links for n in link.nodes]
            if self.system.element == "ancf" else []) if exact_hold else None
        self._applied = np.zeros(4)  # the loads held now: τ1, τ2, Fx, Fy
        self._index_state()
        self._readout = new_readout(self.system.element == "ancf", *self._joint_arrays(),
                                    *self.fields[0].compiled(), *self.fields[1].compiled())
        self._truth = None
        self._steps = 0
        Plant.__init__(self, sensors, basis)
        self._cache = None  # state readout of the current step (see _read)
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
        return 2 * (2 + sum(m.n for m in self.modal_basis))

    def reset(self, state0=None) -> Measurement:
        """Start at t = 0 from ``state0`` = [θ, q, θ̇, q̇] (q in the modal basis, length
        2·(2 + n1 + n2)); default: at rest, undeformed, θ = 0.  The FE nodes are placed on
        the inextensible curve with that modal deflection."""
        n = self.state_size // 2
        x0 = np.zeros(2 * n) if state0 is None else np.asarray(state0, dtype=float)
        if x0.shape != (2 * n,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"state0 must be {2 * n} finite numbers [theta, q, theta_dot, "
                             f"q_dot], got shape {x0.shape}")
        u = self._node_displacements(x0[:n])
        eps = 1e-6  # central difference along the velocity: exact for the linear part
        v = (self._node_displacements(x0[:n] + eps * x0[n:])
             - self._node_displacements(x0[:n] - eps * x0[n:])) / (2 * eps)
        sd, cfg = self.system.mbs.systemData, exu.ConfigurationType.Initial
        sd.SetODE2Coordinates(u, configuration=cfg)
        sd.SetODE2Coordinates_t(v, configuration=cfg)
        for load in (*self.system.loads, self.system.tip_load):
            self.system.mbs.SetLoadParameter(load, "loadVector", [0.0, 0.0, 0.0])
        self._applied[:] = 0.0
        self.settings.timeIntegration.startTime = 0.0
        if not self.solver.InitializeSolver(self.system.mbs, self.settings):
            raise PlantFailure(f"Exudyn could not initialise the solver: "
                               f"{self.solver.GetErrorString()}")
        self._steps = 0
        self.time = 0.0
        self._cache = self._truth = None
        return self.measure()

    def advance(self, tau, Ts: float, tip_force=None) -> None:
        """Hold joint torques ``tau`` (2,) [N m] and the payload force ``tip_force``
        (Fx, Fy) [N, base frame] for ``Ts`` seconds (an exact zero-order hold,
        `hold_loads`).  Raises `PlantFailure` with Exudyn's message if the solver fails."""
        steps = self.periods(Ts)
        if len(tau) != 2:
            raise ValueError("the Exudyn plant has two actuators: tau must have 2 values, "
                             f"got {len(tau)}")
        fx, fy = (0.0, 0.0) if tip_force is None else (float(tip_force[0]),
                                                       float(tip_force[1]))
        self.hold_loads(float(tau[0]), float(tau[1]), fx, fy)
        self._steps += steps
        self._cache = self._truth = None
        self._iteration.endTime = self._steps * self.h
        if not self.solver.SolveSteps(self.system.mbs, self.settings):
            msg = self.solver.GetErrorString() or "Newton iteration did not converge"
            raise PlantFailure(f"Exudyn solver failed at t = {self._iteration.currentTime:.6g} "
                               f"s: {msg.strip()}")
        self.time = self._steps * self.h

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
        set_load, (l1, l2, l2r) = self._set_load, self.system.loads
        if t1 != applied[0]:
            set_load(l1, "loadVector", [0.0, 0.0, t1])
        if t2 != applied[1]:
            set_load(l2, "loadVector", [0.0, 0.0, t2])
            set_load(l2r, "loadVector", [0.0, 0.0, -t2])
        if fx != applied[2] or fy != applied[3]:
            set_load(self.system.tip_load, "loadVector", [fx, fy, 0.0])
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
        """`truth_vector` written into ``out`` (one compiled call on Exudyn's coordinates)."""
        sd = self._system_data
        readout_into(self._readout, sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), out)

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
        return u

    # --- modal analysis ---------------------------------------------------------------------------
    def natural_frequencies(self, theta=(0.0, 0.0), joints: str = "locked",
                            n: int = 4) -> np.ndarray:
        """First ``n`` bending frequencies [Hz] of this plant's FE model linearised at
        ``theta`` (see `natural_frequencies`)."""
        return natural_frequencies(self.params, self.mesh, theta=theta, joints=joints, n=n)


# --- the truth readout, compiled -----------------------------------------------------------------
_V, _I = types.Array(types.float64, 1, "C"), types.Array(types.int64, 1, "C")
_M, _MI = types.Array(types.float64, 2, "C"), types.Array(types.int64, 2, "C")
_LINK = (("idx", _MI), ("ref", _M), ("hub_idx", _I), ("hub_ref", _V), ("d", _V), ("dd", _V),
         ("projector", _M), ("H_quad", _M), ("phi_T", _M), ("rho_w", _V))  # `LinkField.compiled`


@structref.register
class _ReadoutType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Readout(structref.StructRefProxy):
    """What `readout_into` reads the truth from Exudyn's coordinates with: the joints'
    and tips' indices and reference values, and each link's `LinkField` arrays (one
    structure passed by reference: a call costs ~1 µs, 27 separate arrays cost ~5)."""


structref.define_boxing(_ReadoutType, Readout)
_READOUT = _ReadoutType((("ancf", types.boolean), ("jidx", _I), ("jref", _V),
                         ("tip_idx", _MI), ("tip_ref", _M),
                         *((f"{name}1", typ) for name, typ in _LINK),
                         *((f"{name}2", typ) for name, typ in _LINK)))


@njit(cache=True)
def new_readout(ancf, jidx, jref, tip_idx, tip_ref,
                idx1, ref1, hub_idx1, hub_ref1, d1, dd1, projector1, H_quad1, phi_T1, rho_w1,
                idx2, ref2, hub_idx2, hub_ref2, d2, dd2, projector2, H_quad2, phi_T2, rho_w2):
    """A `Readout` of these arrays (shared, not copied)."""
    r = structref.new(_READOUT)
    r.ancf, r.jidx, r.jref, r.tip_idx, r.tip_ref = ancf, jidx, jref, tip_idx, tip_ref
    r.idx1, r.ref1, r.hub_idx1, r.hub_ref1, r.d1, r.dd1 = idx1, ref1, hub_idx1, hub_ref1, d1, dd1
    r.projector1, r.H_quad1, r.phi_T1, r.rho_w1 = projector1, H_quad1, phi_T1, rho_w1
    r.idx2, r.ref2, r.hub_idx2, r.hub_ref2, r.d2, r.dd2 = idx2, ref2, hub_idx2, hub_ref2, d2, dd2
    r.projector2, r.H_quad2, r.phi_T2, r.rho_w2 = projector2, H_quad2, phi_T2, rho_w2
    return r


@njit(cache=True)
def readout_into(r, u, v, out):
    """The truth vector from Exudyn's ODE2 coordinates ``u`` and rates ``v``, in one
    compiled call (`ExudynPlant._joints` and `LinkField` written out)."""
    n1, n2 = r.projector1.shape[0], r.projector2.shape[0]
    m = 2 + n1 + n2
    jidx, jref = r.jidx, r.jref
    th1 = jref[0] + u[jidx[0]]
    hub2 = jref[1] + u[jidx[1]]
    if r.ancf:
        sx, sy = jref[2] + u[jidx[2]], jref[3] + u[jidx[3]]
        sxd, syd = v[jidx[2]], v[jidx[3]]
        c, s = np.cos(th1), np.sin(th1)
        tangent = th1 + np.arctan2(-s * sx + c * sy, c * sx + s * sy)
        tangent_rate = (sx * syd - sy * sxd) / (sx * sx + sy * sy)
    else:
        tangent = jref[2] + u[jidx[2]]
        tangent_rate = v[jidx[2]]
    out[0], out[1] = th1, hub2 - tangent
    out[m], out[m + 1] = v[jidx[0]], v[jidx[1]] - tangent_rate
    e = 2 * m
    for k in range(2):
        for j in range(2):
            out[e + 2 * k + j] = r.tip_ref[k, j] + u[r.tip_idx[k, j]]
    out[e + 4], out[e + 6] = link_readout(u, v, r.ancf, r.idx1, r.ref1, r.hub_idx1, r.hub_ref1,
                                          r.d1, r.dd1, r.projector1, r.H_quad1, r.phi_T1,
                                          r.rho_w1, out[2:2 + n1], out[m + 2:m + 2 + n1])
    out[e + 5], out[e + 7] = link_readout(u, v, r.ancf, r.idx2, r.ref2, r.hub_idx2, r.hub_ref2,
                                          r.d2, r.dd2, r.projector2, r.H_quad2, r.phi_T2,
                                          r.rho_w2, out[2 + n1:m], out[m + 2 + n1:2 * m])
