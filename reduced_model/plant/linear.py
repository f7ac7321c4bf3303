"""The reduced model linearised about rest (the paper's eq. 1–3), as a python-control
`StateSpace` with the outputs both plants' linear models share."""
from __future__ import annotations

import numpy as np

from ..contract import motor_outputs, output_names
from ..joints import with_joints
from ..model import ArmModel
from ..shapes import LinkModes, projection

__all__ = ["reduced_linear_model"]


def reduced_linear_model(model: ArmModel, *, theta=None, Ts: float | None = None,
                         modal_basis: tuple[LinkModes, ...] | None = None,
                         generalised_forces: bool = False):
    """The reduced model linearised about rest at joint angles ``theta``
    (`ArmModel.linearize`, exact), with the outputs of `plant_exudyn.linear_model`
    (`output_names`) and the linear part of its arm's joints (`with_joints`: drives,
    viscous friction, current loops; dry friction and backlash are nonlinear and left
    out, `nonlinear_joint_effects`).

    Parameters
    ----------
    model : ArmModel
        The reduced model (its parameters and modes per link).
    theta : sequence of float, optional
        The joint angles [rad] of the configuration (default: all 0).
    Ts : float, optional
        If given, the exact zero-order-hold discretisation at this period [s].
    modal_basis : tuple of LinkModes, optional
        Mode shapes to express the q outputs in (default: the model's own); another basis
        receives the model's deflection by the same weighted projection as `ReducedPlant`.
    generalised_forces : bool
        Inputs on every coordinate (``tau1``, ``tau2``, then ``f_q11``… [N]): what the
        idealised PBC applies; default: the joint torques only.

    Returns
    -------
    control.StateSpace
        Inputs ``tau1`` … ``tauN`` [N m] (and the modal forces); outputs θ, q, θ̇, q̇,
        the tip deflections and the motors (deviations: rad, m, rad/s, m/s);
        states ``model.state_names`` (then the drives' and lags', `with_joints`).
    """
    import control  # loaded by the linear verdicts that use it
    n, N = model.n, model.n_joints
    Q0 = np.zeros(n)
    Q0[:N] = 0.0 if theta is None else np.asarray(theta, dtype=float)
    A, B = model.linearize(Q0)
    inputs = [f"tau{i + 1}" for i in range(N)]
    if generalised_forces:
        B = np.vstack([np.zeros((n, n)), np.linalg.inv(model.mass_matrix(Q0))])
        inputs += [f"f_{c}" for c in model.coordinate_names[N:]]
    basis = model.mode_shapes if modal_basis is None else tuple(modal_basis)
    T = np.eye(n - N) if modal_basis is None else projection(model.mode_shapes, basis)
    m = N + T.shape[0]
    Cq = np.zeros((m, n))
    Cq[:N, :N] = np.eye(N)
    Cq[N:, N:] = T
    tips = np.zeros((N, n))
    c = N
    for i, modes in enumerate(model.mode_shapes):
        tips[i, c:c + modes.n] = modes.tip_values[0]
        c += modes.n
    C = np.block([[Cq, np.zeros((m, n))], [np.zeros((m, n)), Cq], [tips, np.zeros((N, n))]])
    arm = control.ss(A, B, C, np.zeros((C.shape[0], len(inputs))), inputs=inputs,
                     outputs=list(output_names(tuple(m.n for m in basis))[:-2 * N]),
                     states=list(model.state_names),
                     name="reduced_" + "_".join(str(k) for k in model.modes_per_link))
    sys_ = with_joints(arm, model.params)
    return sys_ if Ts is None else control.sample_system(sys_, Ts, method="zoh",
                                                         name=sys_.name + "_zoh")
