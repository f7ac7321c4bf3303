"""The reduced model: the Euler–Lagrange assumed-modes model of a planar N-link arm (the
paper's eq. 1–3 and 22 for its two links, De Luca and Siciliano's closed form).

M(Q) Q̈ + C(Q, Q̇) Q̇ + D Q̇ + K Q + ∂V_g/∂Q = B τ,   B = [I_N; 0],

with the Kelvin–Voigt damping D Q̇ the paper leaves out and the potential V_g of gravity
in the arm's plane (the paper's g(Q) is the elastic force K Q of a horizontal arm).
"""
from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from .arm import ArmParameters, MAX_MODES
from .code.cache_guard import fresh_kernel_caches
from .contract.signals import coordinate_names
from .dynamics import LinkPack, kernels, new_workspace, pack_model
from .shapes import InextensibleLink, LinkModes, gauss_legendre, interpolation_nodes

__all__ = ["ArmModel", "validate_modes_per_link", "validate_kinematics", "cached_model",
           "KINEMATICS"]

#: The kinematics of a link's points: the paper's x + i w (linear in the modal
#: coordinates), or the exact inextensible centreline (`reduced_model.shapes.inextensible`).
KINEMATICS = ("linear", "exact")


def validate_modes_per_link(modes_per_link, arm: ArmParameters | None = None, *,
                            where: str = "modes_per_link") -> tuple[int, ...]:
    """``modes_per_link`` checked: one whole number of assumed modes per link, 1..4 for a
    flexible link and 0 for a rigid one (``arm``: the arm they are for; None: any arm).

    Parameters
    ----------
    modes_per_link : sequence
        The modes of each link, from the base out.
    arm : ArmParameters, optional
        The arm: its number of links, and which are rigid.
    where : str
        The key named in the error.

    Returns
    -------
    tuple of int

    Raises
    ------
    ValueError
        Naming ``where`` and the value, for anything else.

    Examples
    --------
    >>> from reduced_model import validate_modes_per_link
    >>> validate_modes_per_link([2, 3])
    (2, 3)
    """
    ok = (isinstance(modes_per_link, Sequence) and not isinstance(modes_per_link, str)
          and 1 <= len(modes_per_link) <= 4
          and all(isinstance(m, (int, np.integer)) and not isinstance(m, bool)
                  and 0 <= m <= MAX_MODES for m in modes_per_link))
    if not ok:
        raise ValueError(f"{where} must be one integer in 0..{MAX_MODES} per link (0: rigid), "
                         f"got {modes_per_link!r}")
    modes = tuple(int(m) for m in modes_per_link)
    if arm is not None:
        if len(modes) != arm.n_links:
            raise ValueError(f"{where} must have one entry per link ({arm.n_links}), got "
                             f"{list(modes)!r}")
        for i, (m, link) in enumerate(zip(modes, arm.links)):
            if (m == 0) != link.rigid:
                kind = "rigid: 0" if link.rigid else "flexible: 1..4"
                raise ValueError(f"{where}: link {i + 1} is {kind} modes, got {list(modes)!r}")
    return modes


def validate_kinematics(kinematics, *, where: str = "kinematics") -> str:
    """Return ``kinematics`` if it is one of `KINEMATICS`, or raise ValueError."""
    if not isinstance(kinematics, str) or kinematics not in KINEMATICS:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, KINEMATICS))}, "
                         f"got {kinematics!r}")
    return kinematics


@functools.lru_cache(maxsize=32)
def cached_model(params: ArmParameters, modes_per_link: tuple[int, ...] | None = None,
                 kinematics: str = "linear") -> "ArmModel":
    """The `ArmModel` of ``params``, ``modes_per_link`` and ``kinematics``, built once per
    process (~20 ms each; the runs of a sweep share most).  Users must not mutate it; its
    own methods' scratch space is shared, so use it from one thread."""
    return ArmModel(params, modes_per_link, kinematics)


def _gram(basis: np.ndarray, basis_tip: np.ndarray, rho: float, w: np.ndarray,
          tip_point_mass: float) -> np.ndarray:
    """G = ∫ρ b bᵀ dx + m_tip b(L) b(L)ᵀ from the basis at the quadrature points."""
    return rho * (basis * w) @ basis.T + tip_point_mass * np.outer(basis_tip, basis_tip)


def _link_stiffness(modes: LinkModes, EI: float) -> np.ndarray:
    """K_i = EI ∫ φ'' φ''ᵀ dx (diagonal, = m_i ω_j², for exact eigenfunctions)."""
    x, w = gauss_legendre(0.0, modes.L)
    curv = modes.ddphi(x)
    return EI * (curv * w) @ curv.T


class ArmModel:
    """Reduced (assumed-modes) model of a planar serial arm (`ArmParameters`).

    Coordinates ``Q = [θ_1 … θ_N, q_11 … q_1n1, …, q_N1 … q_NnN]`` (the paper's order for
    two links of two modes: [θ1, θ2, q11, q12, q21, q22]).  θ1 is hub 1's angle from the
    base x axis; θ_i (i > 1) is hub i's angle *relative to link i−1's tip tangent* (what
    its encoder reads).  q_ij are the amplitudes of the clamped-mass modes φ_ij of link i
    (`mode_shapes`), with deflection w_i(x) = Σ_j φ_ij(x) q_ij in link i's root frame; a
    rigid link has none.  The state is ``x = [Q, Q̇]``.

    Kinematics.  ``"linear"`` (the paper's): a point of link i at x is at x + i w_i(x)
    in its root frame, and the tip slope turns the next frame by w_i'(L_i).  ``"exact"``:
    the same coordinates and mode shapes fix the slope of an inextensible centreline,
    tan β = w', which keeps its arc length (foreshortening included) and turns the next
    frame by atan w_i'(L_i) — the FE plant's placement of its nodes; its bending energy
    is ½ EI ∫ κ² of the exact curvature κ = β'.  Both have the same mass matrix at q = 0,
    hence the same linearisation about rest in a horizontal plane.

    All configuration-independent integrals are computed once here; the hot functions run
    as numba kernels (`reduced_model.dynamics`) on `packed` and can be called from other
    compiled code.  The methods below allocate their outputs and are meant for analysis,
    tests and set-up, not for inner loops.

    Parameters
    ----------
    params : ArmParameters
        Physical arm (default: the default arm).
    modes_per_link : sequence of int, optional
        Assumed modes of each link, 1..4 for a flexible link, 0 for a rigid one (default:
        the arm's ``modes``; the paper: 2, 2).
    kinematics : {"linear", "exact"}
        The paper's linear kinematics (default) or exact inextensible kinematics.
    """

    def __init__(self, params: ArmParameters | None = None,
                 modes_per_link: Sequence[int] | None = None,
                 kinematics: str = "linear") -> None:
        fresh_kernel_caches()  # before any kernel runs: every kernel works on a model
        self.params = p = params if params is not None else ArmParameters()
        self.modes_per_link = validate_modes_per_link(
            p.modes() if modes_per_link is None else modes_per_link, p)
        self.kinematics = validate_kinematics(kinematics)
        self.exact = self.kinematics == "exact"
        #: N: the links (and joints, each at its link's root).
        self.n_joints = N = p.n_links
        self.mode_shapes = tuple(
            LinkModes(L=link.length, rho=link.mass_per_length, EI=link.bending_stiffness,
                      tip_mass=p.tip_load(i)[0], tip_inertia=p.tip_load(i)[1], n=m)
            for i, (link, m) in enumerate(zip(p.links, self.modes_per_link)))
        self.n = N + sum(self.modes_per_link)
        #: Each link's exact kinematics (`InextensibleLink`; None for a rigid link); none
        #: for the linear model.
        nodes = interpolation_nodes(self.modes_per_link)
        self.links = tuple(InextensibleLink(m, nodes) if m.n else None
                           for m in self.mode_shapes) if self.exact else ()
        K, D = np.zeros((self.n, self.n)), np.zeros((self.n, self.n))
        axes = np.zeros((2 * N, self.n))  # rotor rows: hub 1, tip 1, hub 2, …
        c = N
        for i, (link, modes) in enumerate(zip(p.links, self.mode_shapes)):
            axes[2 * i:, i] = 1.0
            if modes.n:
                block = slice(c, c + modes.n)
                Ki = _link_stiffness(modes, link.bending_stiffness)
                K[block, block] = Ki
                D[block, block] = link.bending_damping / link.bending_stiffness * Ki
                axes[2 * i + 1:, block] = modes.tip_values[1]
            c += modes.n
        self._rotor_axes = axes
        M_rotors = axes.T @ np.diag(p.rotor_inertias()) @ axes
        #: The model packed for compiled code (`reduced_model.dynamics.layout`).
        self.packed = pack_model([self._link_pack(i) for i in range(N)], M_rotors=M_rotors,
                                 K=K, D=D, gravity=p.gravity)
        self._K, self._D = K, D
        #: The compiled entry points of this model's kinematics.
        self.kernels = kernels(self.exact)
        self._work = self.new_workspace()

    def _link_pack(self, i: int) -> LinkPack:
        """Link ``i``'s constants for `pack_model`: its Gram matrix (link 0's basis has no
        constant: its root never moves), tip values, exact-kinematics nodes, first moments."""
        p, modes = self.params, self.mode_shapes[i]
        link = p.links[i]
        x, w = gauss_legendre(0.0, modes.L)
        end = np.array([modes.L])
        exact = self.links[i] if self.exact else None
        basis = [np.ones_like(x), x, modes.phi(x)]
        tip = [[1.0, modes.L], modes.phi(end)[:, 0]]
        if exact is not None:
            basis.append(exact.r(x))
            tip.append(exact.r(end)[:, 0])
        basis, tip = np.vstack(basis), np.concatenate(tip)
        moment = modes.rho * basis @ w + p.tip_point_mass(i) * tip
        if i == 0:
            basis, tip, moment = basis[1:], tip[1:], moment[1:]
        G = _gram(basis, tip, modes.rho, w, p.tip_point_mass(i))
        nodes = exact.nodes if exact is not None else 0
        rotor_tip = p.rotor_inertias()[2 * i + 1]
        empty = np.zeros((modes.n, nodes))
        return LinkPack(n=modes.n, nodes=nodes, L=modes.L, EI=link.bending_stiffness,
                        damping=link.bending_damping, J_hub=link.hub_inertia, J_tip=rotor_tip,
                        G=G, phi_tip=modes.tip_values[0], dphi_tip=modes.tip_values[1],
                        dphi=exact.dphi if exact is not None else empty,
                        ddphi=exact.ddphi if exact is not None else empty,
                        w=exact.weights if exact is not None else np.zeros(0), moment=moment)

    def new_workspace(self) -> tuple[np.ndarray, np.ndarray]:
        """Fresh scratch space for the kernels: the packed (complex, real) buffers."""
        return new_workspace(self.packed[0])

    # --- names -------------------------------------------------------------------
    @property
    def coordinate_names(self) -> tuple[str, ...]:
        return coordinate_names(self.modes_per_link)

    @property
    def state_names(self) -> tuple[str, ...]:
        names = self.coordinate_names
        return names + tuple(f"{c}_dot" for c in names)

    def _vec(self, v, length: int, name: str) -> np.ndarray:
        arr = np.ascontiguousarray(v, dtype=float)
        if arr.shape != (length,):
            raise ValueError(f"{name} must have shape ({length},), got {arr.shape}")
        return arr

    # --- dynamics ------------------------------------------------------------------
    def mass_matrix(self, Q) -> np.ndarray:
        """Inertia matrix M(Q), symmetric positive definite (n, n)."""
        M = np.empty((self.n, self.n))
        self.kernels.mass_matrix(*self.packed, *self._work, self._vec(Q, self.n, "Q"), M)
        return M

    def coriolis_matrix(self, Q, Qdot) -> np.ndarray:
        """Coriolis/centrifugal matrix C(Q, Q̇) from Christoffel symbols (Ṁ − 2C skew)."""
        C = np.empty((self.n, self.n))
        self.kernels.coriolis(*self.packed, *self._work, self._vec(Q, self.n, "Q"),
                              self._vec(Qdot, self.n, "Qdot"), C)
        return C

    def stiffness_matrix(self) -> np.ndarray:
        """K = blockdiag(0, K_1, …), K_i = EI_i ∫φ_i''φ_i''ᵀ (diag(m_i ω_ij²))."""
        return self._K.copy()

    def damping_matrix(self) -> np.ndarray:
        """D = blockdiag(0, d_1/EI_1 K_1, …) (Kelvin–Voigt bending damping)."""
        return self._D.copy()

    def input_matrix(self) -> np.ndarray:
        """B = [I_N; 0] (n, N): only the joints are actuated."""
        return np.eye(self.n, self.n_joints)

    def acceleration(self, Q, Qdot, tau) -> np.ndarray:
        """Q̈ from joint torques ``tau`` (N,) — or generalised forces (n,)."""
        tau = np.ascontiguousarray(tau, dtype=float)
        if tau.shape not in ((self.n_joints,), (self.n,)):
            raise ValueError(f"tau must have shape ({self.n_joints},) or ({self.n},), got "
                             f"{tau.shape}")
        out = np.empty(self.n)
        self.kernels.acceleration(*self.packed, *self._work, self._vec(Q, self.n, "Q"),
                                  self._vec(Qdot, self.n, "Qdot"), tau, out)
        return out

    def rhs(self, x, tau) -> np.ndarray:
        """ẋ = f(x, τ) for the state x = [Q, Q̇] (2n,)."""
        x = self._vec(x, 2 * self.n, "x")
        return np.concatenate([x[self.n:], self.acceleration(x[:self.n], x[self.n:], tau)])

    def gravity_force(self, Q) -> np.ndarray:
        """∂V_g/∂Q (n,): the generalised force of gravity the arm must resist at rest at
        ``Q`` (zero for a horizontal arm)."""
        M, h = np.empty((self.n, self.n)), np.empty(self.n)
        self.kernels.bias(*self.packed, *self._work, self._vec(Q, self.n, "Q"), np.zeros(self.n),
                          M, h)
        return h

    def elastic_force(self, Q, Qdot) -> np.ndarray:
        """K Q + D Q̇ (exact kinematics: the exact bending forces) (n,)."""
        f = np.empty(self.n)
        self.kernels.elastic(*self.packed, self._vec(Q, self.n, "Q"),
                             self._vec(Qdot, self.n, "Qdot"), f)
        return f

    def kinetic_energy(self, Q, Qdot) -> float:
        Qdot = self._vec(Qdot, self.n, "Qdot")
        return 0.5 * float(Qdot @ self.mass_matrix(Q) @ Qdot)

    def potential_energy(self, Q) -> float:
        """Elastic energy ½ QᵀKQ (exact kinematics: ½ Σ EI ∫ κ² of the exact curvature)
        plus the potential of gravity, −Σ ∫ ρ g·r − Σ m g·r over every link and point mass
        (zero at the base; 0 for a horizontal arm)."""
        Q = self._vec(Q, self.n, "Q")
        energy = 0.5 * float(Q @ self._K @ Q)
        for link, (q, _), lp in zip(self.links, self._link_coordinates(Q, Q), self.params.links):
            if link is not None:
                energy += link.energy_correction(q, lp.bending_stiffness)
        g = complex(*self.params.gravity)
        if g != 0:
            energy -= sum((np.conj(g) * z * m).real for z, m in self._mass_points(Q))
        return energy

    def _mass_points(self, Q):
        """(position, mass) pairs that integrate every link's mass and its tip mass
        (96-point Gauss quadrature per link; exact for the polynomial kinematics)."""
        p = self.params
        out = []
        z_root, alpha = 0j, 0.0
        for i, (modes, (q, _)) in enumerate(zip(self.mode_shapes, self._link_coordinates(Q, Q))):
            alpha += Q[i]
            x, w = gauss_legendre(0.0, modes.L)
            points = np.append(x, modes.L)
            masses = np.append(modes.rho * w, p.tip_point_mass(i))
            centre = self._centreline(i, points, q)
            e = np.exp(1j * alpha)
            out += list(zip(z_root + e * centre, masses))
            z_root = z_root + e * centre[-1]
            slope = modes.tip_values[1] @ q if modes.n else 0.0
            alpha += np.arctan(slope) if self.exact else slope
        return out

    def _centreline(self, i: int, s, q) -> np.ndarray:
        """Points of link ``i``'s centreline at arc lengths ``s`` in its root frame."""
        modes = self.mode_shapes[i]
        if not modes.n:
            return np.asarray(s, dtype=complex)
        z = np.asarray(s, dtype=float) + 1j * (modes.phi(s).T @ q)
        if self.exact:
            z = z + self.links[i].r(s).T @ self.links[i].remainder(q)
        return z

    def _link_coordinates(self, Q, Qdot):
        out, c = [], self.n_joints
        for m in self.modes_per_link:
            out.append((Q[c:c + m], Qdot[c:c + m]))
            c += m
        return out

    def _elastic_matrices(self, Q) -> tuple[np.ndarray, np.ndarray]:
        """The tangent stiffness and the damping matrix at rest at ``Q``: K and D, plus the
        exact bending terms' for exact kinematics."""
        K, D = self._K.copy(), self._D.copy()
        c = self.n_joints
        for link, (q, _), lp, m in zip(self.links or (None,) * self.n_joints,
                                       self._link_coordinates(Q, Q), self.params.links,
                                       self.modes_per_link):
            if link is not None:
                b = slice(c, c + m)
                K[b, b] += link.stiffness_correction(q, lp.bending_stiffness)
                D[b, b] += link.damping_correction(q, lp.bending_damping)
            c += m
        return K, D

    # --- kinematics ------------------------------------------------------------------
    def tip_deflection(self, Q) -> np.ndarray:
        """Tip deflections [m] across each link's root frame, w_i(L_i) (exact kinematics:
        the tips' transverse positions), (N,)."""
        return self._tips(Q)[2 * self.n_joints:]

    def tip_position(self, Q) -> np.ndarray:
        """Planar positions [m] of each link's tip (the last is the payload): array (N, 2),
        rows = tips, columns = (x, y).  Includes deflection."""
        return self._tips(Q)[:2 * self.n_joints].reshape(self.n_joints, 2)

    def _tips(self, Q) -> np.ndarray:
        out = np.empty(3 * self.n_joints)
        self.kernels.tips(*self.packed, self._vec(Q, self.n, "Q"), out)
        return out

    def tip_jacobian(self, Q) -> np.ndarray:
        """∂(payload position)/∂Q, shape (2, n): maps a tip force F to generalised forces
        Jᵀ F.  With z the payload position as a complex number and z_i the roots of the
        links: ∂z/∂θ_i = i (z − z_i); ∂z/∂q_ik = i e^{iα_i} φ_ik(L_i) + i φ_ik'(L_i)
        (z − z_i(L_i)) (exact kinematics: `reduced_model.dynamics.exact`)."""
        Q = self._vec(Q, self.n, "Q")
        if self.exact:
            J = np.empty((2, self.n))
            self.kernels.tip_jacobian(*self.packed, *self._work, Q, J)
            return J
        N, c = self.n_joints, self.n_joints
        defl = self.tip_deflection(Q)
        alpha, offsets, frames = Q[0], [], []  # each link's tip from its root, its e^{iα}
        for i, modes in enumerate(self.mode_shapes):
            if i:
                alpha = alpha + Q[i] + slope
            e = np.exp(1j * alpha)
            offsets.append(e * (modes.L + 1j * defl[i]))
            frames.append(e)
            slope = modes.tip_values[1] @ Q[c:c + modes.n]
            c += modes.n
        beyond = [offsets[-1]]  # z − (root of link i), summed from the payload in
        for o in offsets[-2::-1]:
            beyond.insert(0, o + beyond[0])
        dz = np.zeros(self.n, dtype=complex)
        c = N
        for i, modes in enumerate(self.mode_shapes):
            dz[i] = 1j * beyond[i]
            phi, dphi = modes.tip_values
            dz[c:c + modes.n] = 1j * frames[i] * phi + (
                1j * dphi * beyond[i + 1] if i + 1 < N else 0)
            c += modes.n
        return np.vstack([dz.real, dz.imag])

    # --- linear analysis -------------------------------------------------------------
    def natural_frequencies(self, Q=None, joints: str = "locked") -> np.ndarray:
        """Undamped natural frequencies [Hz] of the model linearised at ``Q``.

        ``joints="locked"``: θ held fixed, the flexible modes.  ``joints="free"``: the
        non-zero frequencies of the free arm (its N rigid-body zeros dropped; in gravity
        the arm is not at rest unless held, so only ``"locked"`` is asked of it).  ``Q``
        defaults to the zero configuration.
        """
        import scipy.linalg  # 0.13 s to import: not for a command that builds no model
        Q = np.zeros(self.n) if Q is None else self._vec(Q, self.n, "Q")
        M, K = self.mass_matrix(Q), self._elastic_matrices(Q)[0]
        N = self.n_joints
        if joints == "locked":
            w2 = scipy.linalg.eigh(K[N:, N:], M[N:, N:], eigvals_only=True)
        elif joints == "free":
            w2 = scipy.linalg.eigh(K, M, eigvals_only=True)[N:]
        else:
            raise ValueError(f"joints must be 'locked' or 'free', got {joints!r}")
        return np.sqrt(np.clip(w2, 0.0, None)) / (2.0 * np.pi)

    def linearize(self, Q0=None, tau0=None) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) of ẋ ≈ A δx + B δτ about the rest state x = [Q0, 0] with torque tau0.

        Exact (no finite differences) in a horizontal plane: ∂Q̈/∂Q_k = −M⁻¹(K e_k +
        ∂M/∂Q_k Q̈0), with ∂M/∂Q_k = C(Q0, e_k) + C(Q0, e_k)ᵀ; Coriolis terms are quadratic
        in Q̇ and drop out.  K and D are the tangent stiffness and the damping at Q0
        (exact kinematics: with the exact curvature's terms, which vanish at q = 0).  In
        gravity, the gravity force's Jacobian (central differences, step 1e-6) adds to K.
        """
        n, N = self.n, self.n_joints
        Q0 = np.zeros(n) if Q0 is None else self._vec(Q0, n, "Q0")
        tau0 = np.zeros(N) if tau0 is None else self._vec(tau0, N, "tau0")
        M = self.mass_matrix(Q0)
        (K, D), Bin = self._elastic_matrices(Q0), self.input_matrix()
        gravity = any(self.params.gravity)
        if gravity:
            step = 1e-6
            K = K + np.column_stack([
                (self.gravity_force(Q0 + step * e) - self.gravity_force(Q0 - step * e))
                / (2 * step) for e in np.eye(n)])
        Minv = np.linalg.inv(M)
        force = K @ Q0 if not gravity else self.elastic_force(Q0, np.zeros(n)) \
            + self.gravity_force(Q0)
        qdd0 = Minv @ (Bin @ tau0 - force)
        dfdQ = np.empty((n, n))
        for k in range(n):
            Ck = self.coriolis_matrix(Q0, np.eye(n)[k])
            dfdQ[:, k] = K[:, k] + (Ck + Ck.T) @ qdd0
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ dfdQ, -Minv @ D]])
        B = np.vstack([np.zeros((n, N)), Minv @ Bin])
        return A, B
