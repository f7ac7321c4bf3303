"""The paper's Euler–Lagrange assumed-modes model of the two-link arm (eq. 1–3, 22).

M(Q) Q̈ + C(Q, Q̇) Q̇ + D Q̇ + K Q = B τ,   B = [I2; 0],
in the horizontal plane (the paper's g(Q) becomes the elastic force K Q, plus the
Kelvin–Voigt damping D Q̇ the paper leaves out).
"""
from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from . import _exact_kernels as exact_kern
from . import _kernels as kern
from ._cache_guard import fresh_kernel_caches
from ._inextensible import InextensibleLink, interpolation_nodes
from ._modes import LinkModes, gauss_legendre
from ._parameters import ArmParameters
from ._plant_interface import coordinate_names

__all__ = ["ArmModel", "validate_modes_per_link", "validate_kinematics", "cached_model",
           "KINEMATICS"]

MAX_MODES = 4
#: The kinematics of a link's points: the paper's x + i w (linear in the modal
#: coordinates), or the exact inextensible centreline (`reduced_model._inextensible`).
KINEMATICS = ("linear", "exact")


def validate_modes_per_link(modes_per_link, *, where: str = "modes_per_link") -> tuple[int, int]:
    """``modes_per_link`` checked: two whole numbers of assumed modes, each 1..4.

    Parameters
    ----------
    modes_per_link : sequence
        The modes of link 1 and link 2.
    where : str
        The key named in the error.

    Returns
    -------
    (int, int)

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
    if (
        not isinstance(modes_per_link, Sequence)
        or isinstance(modes_per_link, str)
        or len(modes_per_link) != 2
        or not all(isinstance(m, (int, np.integer)) and not isinstance(m, bool)
                   for m in modes_per_link)
        or not all(1 <= m <= MAX_MODES for m in modes_per_link)
    ):
        raise ValueError(
            f"{where} must be two integers in 1..{MAX_MODES} (modes of link 1, link 2), "
            f"got {modes_per_link!r}"
        )
    return int(modes_per_link[0]), int(modes_per_link[1])


def validate_kinematics(kinematics, *, where: str = "kinematics") -> str:
    """Return ``kinematics`` if it is one of `KINEMATICS`, or raise ValueError."""
    if not isinstance(kinematics, str) or kinematics not in KINEMATICS:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, KINEMATICS))}, "
                         f"got {kinematics!r}")
    return kinematics


@functools.lru_cache(maxsize=32)
def cached_model(params: ArmParameters, modes_per_link: tuple[int, int],
                 kinematics: str = "linear") -> "ArmModel":
    """The `ArmModel` of ``params``, ``modes_per_link`` and ``kinematics``, built once per
    process (~20 ms each; the runs of a sweep share most).  Users must not mutate it; its
    own methods' scratch space is shared, so use it from one thread."""
    return ArmModel(params, modes_per_link, kinematics)


def _gram(modes: LinkModes, tip_point_mass: float, *, with_constant: bool) -> np.ndarray:
    """G = ∫ρ b bᵀ dx + m_tip b(L) b(L)ᵀ for the basis b = [1, x, φ_1, …, φ_n]
    (without the leading 1 unless ``with_constant``)."""
    x, w = gauss_legendre(0.0, modes.L)
    end = np.array([modes.L])
    basis = np.vstack([np.ones_like(x), x, modes.phi(x)])
    basis_tip = np.concatenate([[1.0, modes.L], modes.phi(end)[:, 0]])
    if not with_constant:
        basis, basis_tip = basis[1:], basis_tip[1:]
    return modes.rho * (basis * w) @ basis.T + tip_point_mass * np.outer(basis_tip, basis_tip)


def _link_stiffness(modes: LinkModes, EI: float) -> np.ndarray:
    """K_i = EI ∫ φ'' φ''ᵀ dx (diagonal, = m_i ω_j², for exact eigenfunctions)."""
    x, w = gauss_legendre(0.0, modes.L)
    curv = modes.ddphi(x)
    return EI * (curv * w) @ curv.T


class ArmModel:
    """Reduced (assumed-modes) model of the planar two-link lightweight arm.

    Coordinates ``Q = [θ1, θ2, q_11, …, q_1n1, q_21, …, q_2n2]`` (the paper's order for
    n1 = n2 = 2: [θ1, θ2, q11, q12, q21, q22]).  θ1 is hub 1's angle from the base x
    axis; θ2 is hub 2's angle *relative to the link-1 tip tangent* (what a motor-2
    encoder reads), so link 2's root frame is at θ1 + θ2 + w1'(L1).  q_ij are the
    amplitudes of the clamped-mass modes φ_ij of link i (`mode_shapes`), with
    deflection w_i(x) = Σ_j φ_ij(x) q_ij in link i's root frame.  The state is
    ``x = [Q, Q̇]``.

    Kinematics.  ``"linear"`` (the paper's): a point of link i at x is at x + i w_i(x)
    in its root frame, and the tip slope turns the next frame by w_i'(L_i).  ``"exact"``:
    the same coordinates and mode shapes fix the slope of an inextensible centreline,
    tan β = w', which keeps its arc length (foreshortening included) and turns the next
    frame by atan w_i'(L_i) — the FE plant's placement of its nodes; its bending energy
    is ½ EI ∫ κ² of the exact curvature κ = β' (`reduced_model._inextensible`).  Both
    have the same mass matrix at q = 0, hence the same linearisation about rest; the
    exact model is derived on the docs' theory page.

    All configuration-independent integrals are computed once here; the hot functions
    run as numba kernels (`reduced_model._kernels`) on `data` and can be called from
    other compiled code.  The methods below allocate their outputs and are meant for
    analysis, tests and set-up, not for inner loops.

    Parameters
    ----------
    params : ArmParameters
        Physical arm (defaults: the paper's Table 1).
    modes_per_link : (int, int)
        Assumed modes of link 1 and link 2, each 1..4 (the paper: 2, 2).
    kinematics : {"linear", "exact"}
        The paper's linear kinematics (default) or exact inextensible kinematics.
    """

    def __init__(self, params: ArmParameters | None = None,
                 modes_per_link: tuple[int, int] = (2, 2), kinematics: str = "linear") -> None:
        fresh_kernel_caches()  # before any kernel runs: every kernel works on a model
        self.params = params if params is not None else ArmParameters()
        n1, n2 = validate_modes_per_link(modes_per_link)
        self.modes_per_link = (n1, n2)
        self.kinematics = validate_kinematics(kinematics)
        p = self.params
        tip1, tip2 = p.tip_load(1), p.tip_load(2)
        self.mode_shapes = (
            LinkModes(L=p.L1, rho=p.rho1, EI=p.EI1, tip_mass=tip1[0], tip_inertia=tip1[1], n=n1),
            LinkModes(L=p.L2, rho=p.rho2, EI=p.EI2, tip_mass=tip2[0], tip_inertia=tip2[1], n=n2),
        )
        self.n = 2 + n1 + n2
        m1, m2 = self.mode_shapes
        phi1_tip, dphi1_tip = m1.tip_values
        phi2_tip, dphi2_tip = m2.tip_values

        K = np.zeros((self.n, self.n))
        D = np.zeros((self.n, self.n))
        f1, f2 = slice(2, 2 + n1), slice(2 + n1, self.n)
        K1, K2 = _link_stiffness(m1, p.EI1), _link_stiffness(m2, p.EI2)
        K[f1, f1], K[f2, f2] = K1, K2
        D[f1, f1], D[f2, f2] = p.bending_damping1 / p.EI1 * K1, p.bending_damping2 / p.EI2 * K2

        # Rotors turning at a·Q̇: hub 1 (θ1), stator (θ1 + w1'), hub 2 (α), payload (α + w2').
        axes = np.zeros((4, self.n))
        axes[:, 0] = 1.0
        axes[1:, f1] = dphi1_tip
        axes[2:, 1] = 1.0
        axes[3, f2] = dphi2_tip
        #: Each link's exact kinematics (`InextensibleLink`); none for the linear model.
        self.links = tuple(InextensibleLink(m, interpolation_nodes(self.modes_per_link))
                           for m in self.mode_shapes) if self.kinematics == "exact" else ()
        #: The model packed for compiled code: pass ``packed`` to ``*_packed`` kernels or
        #: `kern.unpack_model(*packed)` inside them.
        self.packed = kern.pack_model(
            n1=n1, n2=n2, L1=p.L1, L2=p.L2,
            gram1=_gram(m1, p.mh2 + p.stator_mass, with_constant=False),
            gram2=_gram(m2, p.Mp, with_constant=True),
            phi1_tip=phi1_tip, dphi1_tip=dphi1_tip, phi2_tip=phi2_tip,
            M_rotors=axes.T @ np.diag([p.Jh1, p.stator_inertia, p.Jh2, p.Jp]) @ axes,
            K=K, D=D, exact=self._exact_parts() if self.kinematics == "exact" else None,
        )
        self.data = kern.unpack_model(*self.packed)
        self._ws = self.new_workspace()[1]

    def _exact_parts(self) -> dict:
        """The constants of the exact kinematics (`reduced_model._exact_kernels.ExactData`)."""
        p = self.params
        l1, l2 = self.links
        return {"G1": l1.gram(p.mh2 + p.stator_mass, with_constant=False),
                "G2": l2.gram(p.Mp, with_constant=True), "dphi1": l1.dphi, "ddphi1": l1.ddphi,
                "dphi2": l2.dphi, "ddphi2": l2.ddphi, "w1": l1.weights, "w2": l2.weights,
                "dphi2_tip": self.mode_shapes[1].tip_values[1],
                "inertia": [p.Jh1, p.stator_inertia, p.Jh2, p.Jp], "EI": [p.EI1, p.EI2],
                "damping": [p.bending_damping1, p.bending_damping2]}

    def new_workspace(self) -> tuple[tuple[np.ndarray, np.ndarray], kern.Workspace]:
        """Fresh scratch space for the kernels: (packed buffers, unpacked `Workspace`)."""
        buffers = kern.new_workspace(self.packed[0])
        return buffers, kern.unpack_workspace(self.packed[0], *buffers)

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
        kern.mass_matrix_into(self.data, self._vec(Q, self.n, "Q"), M, self._ws)
        return M

    def coriolis_matrix(self, Q, Qdot) -> np.ndarray:
        """Coriolis/centrifugal matrix C(Q, Q̇) from Christoffel symbols (Ṁ − 2C skew)."""
        C = np.empty((self.n, self.n))
        kern.coriolis_matrix_into(self.data, self._vec(Q, self.n, "Q"),
                                  self._vec(Qdot, self.n, "Qdot"), C, self._ws)
        return C

    def stiffness_matrix(self) -> np.ndarray:
        """K = blockdiag(0, 0, K1, K2), K_i = EI_i ∫φ_i''φ_i''ᵀ (diag(m_i ω_ij²))."""
        return self.data.K.copy()

    def damping_matrix(self) -> np.ndarray:
        """D = blockdiag(0, 0, d1/EI1 K1, d2/EI2 K2) (Kelvin–Voigt bending damping)."""
        return self.data.D.copy()

    def input_matrix(self) -> np.ndarray:
        """B = [I2; 0] (n, 2): only the two joints are actuated."""
        return np.eye(self.n, 2)

    def acceleration(self, Q, Qdot, tau) -> np.ndarray:
        """Q̈ from joint torques ``tau`` (2,) — or generalised forces (n,)."""
        tau = np.ascontiguousarray(tau, dtype=float)
        if tau.shape not in ((2,), (self.n,)):
            raise ValueError(f"tau must have shape (2,) or ({self.n},), got {tau.shape}")
        out = np.empty(self.n)
        kern.acceleration_into(self.data, self._vec(Q, self.n, "Q"),
                               self._vec(Qdot, self.n, "Qdot"), tau, out, self._ws)
        return out

    def rhs(self, x, tau) -> np.ndarray:
        """ẋ = f(x, τ) for the state x = [Q, Q̇] (2n,)."""
        x = self._vec(x, 2 * self.n, "x")
        return np.concatenate([x[self.n:], self.acceleration(x[:self.n], x[self.n:], tau)])

    def kinetic_energy(self, Q, Qdot) -> float:
        Qdot = self._vec(Qdot, self.n, "Qdot")
        return 0.5 * float(Qdot @ self.mass_matrix(Q) @ Qdot)

    def potential_energy(self, Q) -> float:
        """Elastic energy ½ QᵀKQ (horizontal plane: no gravity); with exact kinematics
        ½ Σ EI ∫ κ² of the exact curvature."""
        Q = self._vec(Q, self.n, "Q")
        energy = 0.5 * float(Q @ self.data.K @ Q)
        p = self.params
        for link, q, EI in zip(self.links, self._link_coordinates(Q), (p.EI1, p.EI2)):
            energy += link.energy_correction(q, EI)
        return energy

    def _link_coordinates(self, Q) -> tuple[np.ndarray, np.ndarray]:
        n1 = self.modes_per_link[0]
        return Q[2:2 + n1], Q[2 + n1:self.n]

    def _elastic_matrices(self, Q) -> tuple[np.ndarray, np.ndarray]:
        """The tangent stiffness and the damping matrix at rest at ``Q``: K and D, plus
        the exact bending terms' for exact kinematics."""
        K, D = self.data.K.copy(), self.data.D.copy()
        p, n1 = self.params, self.modes_per_link[0]
        blocks = (slice(2, 2 + n1), slice(2 + n1, self.n))
        for link, q, b, EI, d in zip(self.links, self._link_coordinates(Q), blocks,
                                     (p.EI1, p.EI2), (p.bending_damping1, p.bending_damping2)):
            K[b, b] += link.stiffness_correction(q, EI)
            D[b, b] += link.damping_correction(q, d)
        return K, D

    # --- kinematics ------------------------------------------------------------------
    def tip_deflection(self, Q) -> np.ndarray:
        """Tip deflections [m] across each link's root frame: w1(L1), w2(L2) (exact
        kinematics: the tips' transverse positions)."""
        return self._tips(Q)[4:]

    def tip_position(self, Q) -> np.ndarray:
        """Planar positions [m] of the link-1 tip (joint 2) and link-2 tip (payload):
        array (2, 2), rows = tips, columns = (x, y).  Includes deflection."""
        return self._tips(Q)[:4].reshape(2, 2)

    def _tips(self, Q) -> np.ndarray:
        out = np.empty(6)
        kern.tip_kinematics_packed(*self.packed, self._vec(Q, self.n, "Q"), out)
        return out

    def tip_jacobian(self, Q) -> np.ndarray:
        """∂(payload position)/∂Q, shape (2, n): maps a tip force F to generalised forces
        Jᵀ F.  With z = payload position as a complex number:
        ∂z/∂θ1 = i z, ∂z/∂θ2 = i r, ∂z/∂q_1k = i e^{iθ1} φ_1k(L1) + i φ_1k'(L1) r,
        ∂z/∂q_2k = i e^{iα} φ_2k(L2), where r = e^{iα}(L2 + i w2(L2)) (exact
        kinematics: `reduced_model._exact_kernels.exact_tip_jacobian_into`)."""
        Q = self._vec(Q, self.n, "Q")
        if self.kinematics == "exact":
            J = np.empty((2, self.n))
            exact_kern.exact_tip_jacobian_into(self.data.exact, self._ws.exact, Q, J)
            return J
        p, n1 = self.params, self.modes_per_link[0]
        (phi1, dphi1), (phi2, _) = self.mode_shapes[0].tip_values, self.mode_shapes[1].tip_values
        w1e, w2e = self.tip_deflection(Q)
        alpha = Q[0] + Q[1] + dphi1 @ Q[2:2 + n1]
        e1, ea = np.exp(1j * Q[0]), np.exp(1j * alpha)
        r = ea * (p.L2 + 1j * w2e)
        z = e1 * (p.L1 + 1j * w1e) + r
        dz = np.concatenate([[1j * z, 1j * r], 1j * e1 * phi1 + 1j * dphi1 * r, 1j * ea * phi2])
        return np.vstack([dz.real, dz.imag])

    # --- linear analysis -------------------------------------------------------------
    def natural_frequencies(self, Q=None, joints: str = "locked") -> np.ndarray:
        """Undamped natural frequencies [Hz] of the model linearised at ``Q``.

        ``joints="locked"``: θ held fixed, the n−2 flexible modes.  ``joints="free"``:
        the n−2 non-zero frequencies of the free arm (the two rigid-body zeros are
        dropped).  ``Q`` defaults to the zero configuration.
        """
        import scipy.linalg  # 0.13 s to import: not for a command that builds no model
        Q = np.zeros(self.n) if Q is None else self._vec(Q, self.n, "Q")
        M, K = self.mass_matrix(Q), self._elastic_matrices(Q)[0]
        if joints == "locked":
            w2 = scipy.linalg.eigh(K[2:, 2:], M[2:, 2:], eigvals_only=True)
        elif joints == "free":
            w2 = scipy.linalg.eigh(K, M, eigvals_only=True)[2:]
        else:
            raise ValueError(f"joints must be 'locked' or 'free', got {joints!r}")
        return np.sqrt(np.clip(w2, 0.0, None)) / (2.0 * np.pi)

    def linearize(self, Q0=None, tau0=None) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) of ẋ ≈ A δx + B δτ about the rest state x = [Q0, 0] with torque tau0.

        Exact (no finite differences): ∂Q̈/∂Q_k = −M⁻¹(K e_k + ∂M/∂Q_k Q̈0), with
        ∂M/∂Q_k = C(Q0, e_k) + C(Q0, e_k)ᵀ; Coriolis terms are quadratic in Q̇ and drop out.
        K and D are the tangent stiffness and the damping at Q0 (exact kinematics: with
        the exact curvature's terms, which vanish at q = 0).
        """
        n = self.n
        Q0 = np.zeros(n) if Q0 is None else self._vec(Q0, n, "Q0")
        tau0 = np.zeros(2) if tau0 is None else self._vec(tau0, 2, "tau0")
        M = self.mass_matrix(Q0)
        (K, D), Bin = self._elastic_matrices(Q0), self.input_matrix()
        Minv = np.linalg.inv(M)
        qdd0 = Minv @ (Bin @ tau0 - K @ Q0)
        dfdQ = np.empty((n, n))
        for k in range(n):
            Ck = self.coriolis_matrix(Q0, np.eye(n)[k])
            dfdQ[:, k] = K[:, k] + (Ck + Ck.T) @ qdd0
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ dfdQ, -Minv @ D]])
        B = np.vstack([np.zeros((n, 2)), Minv @ Bin])
        return A, B
