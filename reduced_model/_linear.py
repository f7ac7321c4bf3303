"""The reduced model linearised about rest (the paper's eq. 1–3), as a python-control
`StateSpace` with the outputs both plants' linear models share."""
from __future__ import annotations

import numpy as np

from ._joint_linear import with_joints
from ._model import ArmModel
from ._modes import LinkModes, projection
from ._plant_interface import MOTOR_OUTPUTS, output_names

__all__ = ["reduced_linear_model"]


def reduced_linear_model(model: ArmModel, *, theta=(0.0, 0.0), Ts: float | None = None,
                         modal_basis: tuple[LinkModes, LinkModes] | None = None,
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
    theta : (float, float)
        θ1, θ2 [rad] of the configuration.
    Ts : float, optional
        If given, the exact zero-order-hold discretisation at this period [s].
    modal_basis : (LinkModes, LinkModes), optional
        Mode shapes to express the q outputs in (default: the model's own); another basis
        receives the model's deflection by the same weighted projection as `ReducedPlant`.
    generalised_forces : bool
        Inputs on every coordinate (``tau1``, ``tau2``, then ``f_q11``… [N]): what the
        idealised PBC applies; default: the two joint torques only.

    Returns
    -------
    control.StateSpace
        Inputs ``tau1``, ``tau2`` [N m] (and the modal forces); outputs θ, q, θ̇, q̇,
        ``tip_defl1``, ``tip_defl2`` and the motors (deviations: rad, m, rad/s, m/s);
        states ``model.state_names`` (then the drives' and lags', `with_joints`).
    """
    import control  # loaded by the linear verdicts that use it
    n = model.n
    Q0 = np.zeros(n)
    Q0[:2] = np.asarray(theta, dtype=float)
    A, B = model.linearize(Q0)
    inputs = ["tau1", "tau2"]
    if generalised_forces:
        B = np.vstack([np.zeros((n, n)), np.linalg.inv(model.mass_matrix(Q0))])
        inputs += [f"f_{c}" for c in model.coordinate_names[2:]]
    basis = model.mode_shapes if modal_basis is None else tuple(modal_basis)
    T = np.eye(n - 2) if modal_basis is None else projection(model.mode_shapes, basis)
    m = 2 + T.shape[0]
    Cq = np.zeros((m, n))
    Cq[:2, :2] = np.eye(2)
    Cq[2:, 2:] = T
    n1 = model.modes_per_link[0]
    tips = np.zeros((2, n))
    tips[0, 2:2 + n1] = model.mode_shapes[0].tip_values[0]
    tips[1, 2 + n1:] = model.mode_shapes[1].tip_values[0]
    C = np.block([[Cq, np.zeros((m, n))], [np.zeros((m, n)), Cq], [tips, np.zeros((2, n))]])
    arm = control.ss(A, B, C, np.zeros((C.shape[0], len(inputs))), inputs=inputs,
                     outputs=list(output_names(tuple(m.n for m in basis))[:-len(MOTOR_OUTPUTS)]),
                     states=list(model.state_names),
                     name=f"reduced_{model.modes_per_link[0]}_{model.modes_per_link[1]}")
    sys_ = with_joints(arm, model.params)
    return sys_ if Ts is None else control.sample_system(sys_, Ts, method="zoh",
                                                         name=sys_.name + "_zoh")
