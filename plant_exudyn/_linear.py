"""The FE arm linearised about a configuration, as a python-control `StateSpace` (the
truth plant's counterpart of the reduced model's linearisation of eq. 1–3).

Exudyn linearises its own equations: ``mbs.ComputeLinearizedSystem`` with
``projectIntoConstraintNullspace=True`` returns M, K, D in the nullspace of the constraint
Jacobian at the configuration (u = Nᵀ z), so the joints and clamps are exact.  Around it:

- inputs: the generalised forces of unit torques τi (hub i, with the reaction −τi on
  link i−1's tip), read as the change of Exudyn's own ODE2 right-hand side when the
  loads are set — the same loads the plant applies;
- outputs: the plant's own readout (`_readout.readout_into`: θ, the modal coordinates q
  projected on ``modal_basis``, their rates, the tip deflections), linearised by central
  differences in the ODE2 coordinates (step 1e-6; the rates are linear in the ODE2
  velocities, so their columns are exact differences);
- states: the mass-normalised modes Φ of the undamped FE arm (Φᵀ M Φ = I, Φᵀ K Φ = Ω²),
  η and η̇, so A = [[0, I], [−Ω², −Φᵀ D Φ]] and the undamped natural frequencies are
  √Ω² / 2π on the diagonal.

Rigid-body modes.  The free arm turns about each of its N joints at no cost; Exudyn's
numerical Jacobian leaves those modes at ~1e-4 Hz (ω² ~ 1e-6 against 190
s⁻² for the first bending mode) instead of 0, and their eigenvectors carry 1e-8 of
deformation.  A spurious spring would put the double pole of each joint at ±j6e-4 rad/s
instead of s = 0 and flip the sign of the response below it, and a rigid mode that the
tip deflections see at 1e-8 puts a double pole at s = 0 into τ → tip deflection — either
of which the ν-gap reports as a distance of 1.  So the rigid modes are set exactly: their
directions are the joint rotations of the exact node placement, with Ω² = 0 and no
damping, and the flexible modes are solved on their M-orthogonal complement (after
checking that K is four orders of magnitude smaller on them than on the first bending
mode).  In gravity the joint rotations are not rigid-body modes and rest is not an
equilibrium of the undeformed arm: the linearisation is for a horizontal arm.
"""
from __future__ import annotations

import control
import exudyn as exu
import numpy as np
import scipy.linalg

from reduced_model import output_names, truth_extras

from ._build import simulation_settings
from ._readout import readout_into

__all__ = ["linearise"]

_FD_STEP = 1e-6  # m, rad or slope: central differences of a smooth readout, error ~1e-10
_RIGID_RATIO = 1e-4  # a "rigid" mode's ω² must be below this × the first flexible one's


def linearise(plant, *, theta=None) -> control.StateSpace:
    """The FE arm of ``plant`` (an `ExudynPlant` of a horizontal arm with ideal joints,
    reset here) linearised about rest at joint angles ``theta`` (default 0; module
    docstring; `plant_exudyn.linear_model` adds the joints)."""
    n, N = plant.state_size // 2, plant.n_joints
    if any(plant.params.gravity):
        raise ValueError("the FE linear model is about rest of a horizontal arm; this arm "
                         f"is in gravity {plant.params.gravity}")
    x0 = np.zeros(2 * n)
    if theta is not None:
        x0[:N] = np.asarray(theta, dtype=float)
    plant.reset(x0)  # the nodes placed exactly at θ: the configuration linearised about
    mbs = plant.system.mbs
    settings = simulation_settings(step=1e-3)
    settings.staticSolver.verboseMode = 0
    M, K, D, _, Nu = mbs.ComputeLinearizedSystem(settings, projectIntoConstraintNullspace=True,
                                                 returnConstraintNullspace=True)
    u0 = np.asarray(mbs.systemData.GetODE2Coordinates(exu.ConfigurationType.Initial), float)
    F = _input_forces(plant, settings)
    Cu, Cv = _output_jacobians(plant, u0)

    Phi, omega2 = _modes(K, M, Nu @ _rigid_motions(plant, x0[:n]))
    Dm = Phi.T @ D @ Phi
    if np.abs(Dm[:N]).max() > 1e-6 * np.abs(Dm).max():
        raise ArithmeticError("the FE damping acts on a rigid-body mode")
    Dm[:N, :] = 0.0
    Dm[:, :N] = 0.0
    k = len(omega2)
    A = np.block([[np.zeros((k, k)), np.eye(k)], [-np.diag(omega2), -Dm]])
    B = np.vstack([np.zeros((k, N)), Phi.T @ Nu @ F])
    C = np.hstack([Cu @ Nu.T @ Phi, Cv @ Nu.T @ Phi])
    states = [f"eta{i + 1}" for i in range(k)]
    counts = "_".join(str(c) for c in plant.mesh.counts(plant.params) if c)
    outputs = output_names(tuple(m.n for m in plant.modal_basis))[:-2 * N]
    return control.ss(A, B, C, np.zeros((C.shape[0], N)),
                      inputs=[f"tau{i + 1}" for i in range(N)], outputs=list(outputs),
                      states=states + [f"{s}_dot" for s in states],
                      name=f"fe_{plant.mesh.element}_{counts or 'rigid'}")


def _rigid_motions(plant, Q0: np.ndarray) -> np.ndarray:
    """ODE2 displacement directions (size, N) of turning each joint at Q0: central
    differences of the exact node placement (`ExudynPlant._node_displacements`); for a
    rotation the difference quotient is parallel to the derivative, so no deformation
    enters."""
    columns = []
    for j in range(plant.n_joints):
        step = np.zeros(len(Q0))
        step[j] = _FD_STEP
        columns.append((plant._node_displacements(Q0 + step)
                        - plant._node_displacements(Q0 - step)) / (2 * _FD_STEP))
    return np.column_stack(columns)


def _modes(K: np.ndarray, M: np.ndarray, rigid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mass-normalised modes Φ (rigid first) and Ω² of (K, M) in nullspace coordinates,
    with the rigid subspace ``rigid`` (nullspace coordinates, N columns) set exactly:
    Ω² = 0 there, and the flexible modes solved on its M-orthogonal complement (module
    docstring).  Exudyn's K gives the rigid motions ω² ~ 1e-6 s⁻² (against 190 for the
    first bending mode); a larger value means they are not rigid: ArithmeticError."""
    r = rigid.shape[1]
    spurious = np.abs(rigid.T @ K @ rigid).max() / np.abs(rigid.T @ M @ rigid).max()
    if r == K.shape[0]:  # every link rigid: no flexible mode
        first = np.inf
    else:
        first = scipy.linalg.eigh(K, M, eigvals_only=True, subset_by_index=[r, r])[0]
    if spurious > _RIGID_RATIO * first:
        raise ArithmeticError(f"joint rotations are not rigid-body modes of the FE arm "
                              f"(ω² = {spurious:.3g} next to {first:.4g} s⁻²)")
    gram = rigid.T @ M @ rigid
    vals, vecs = np.linalg.eigh(gram)
    rigid_modes = rigid @ (vecs / np.sqrt(vals)) @ vecs.T  # Φ_rᵀ M Φ_r = I
    complement = scipy.linalg.null_space((M @ rigid).T)  # zᵀ M Φ_r = 0
    omega2, V = (scipy.linalg.eigh(complement.T @ K @ complement, complement.T @ M @ complement)
                 if complement.shape[1] else (np.zeros(0), np.zeros((0, 0))))
    return (np.hstack([rigid_modes, complement @ V]),
            np.concatenate([np.zeros(r), omega2]))


def _input_forces(plant, settings) -> np.ndarray:
    """Generalised forces (ODE2 size, N) of unit joint torques as the plant applies them
    (`ExudynPlant.step`), from Exudyn's own right-hand side."""
    mbs = plant.system.mbs
    solver = exu.MainSolverStatic()
    solver.InitializeSolver(mbs, settings)
    size = mbs.systemData.ODE2Size()
    N = plant.n_joints

    def rhs(j: int | None) -> np.ndarray:
        plant.set_loads([float(i == j) for i in range(N)] + [0.0, 0.0])
        solver.ComputeODE2RHS(mbs)
        return np.array(solver.GetSystemResidual())[:size]

    r0 = rhs(None)
    forces = np.column_stack([rhs(j) - r0 for j in range(N)])
    rhs(None)
    return forces


def _output_jacobians(plant, u0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """∂y/∂u (central differences) and ∂y/∂v (exact: y is linear in v) of the plant's
    readout at displacements ``u0`` and rest, for the outputs of `output_names`."""
    m = plant.state_size // 2
    extras = truth_extras(plant.n_joints)
    keep = np.r_[0:2 * m, [2 * m + extras.index(f"tip_defl{i + 1}")
                           for i in range(plant.n_joints)]]
    out = np.empty(2 * m + len(extras))

    def read(u, v):
        readout_into(plant._readout, u, v, out)
        return out[keep].copy()

    size = len(u0)
    rest = np.zeros(size)
    y0 = read(u0, rest)
    Cu, Cv = np.empty((len(keep), size)), np.empty((len(keep), size))
    for j in range(size):
        e = np.zeros(size)
        e[j] = _FD_STEP
        Cu[:, j] = (read(u0 + e, rest) - read(u0 - e, rest)) / (2 * _FD_STEP)
        e[j] = 1.0
        Cv[:, j] = read(u0, e) - y0
    return Cu, Cv
