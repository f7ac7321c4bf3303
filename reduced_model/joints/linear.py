"""The arm's joints in a linear model of the arm: drives (gear compliance, gear damping,
reflected rotor inertia), viscous friction and the current loops' lag are linear and are
added exactly; dry friction (Coulomb, stiction) and backlash are not, and are named by
`nonlinear_joint_effects` so that linear verdicts say what they leave out.

The joints act on the arm's joint torque inputs only (`reduced_model.joints.kernels` states
the model), so a linear arm (reduced or FE) with inputs τ_i and outputs θ, θ̇ takes them
by interconnection: per joint i, with u_i the motor torque (the command c_i, or the lag's
state T u̇ = c − u),

- no drive: the arm's input is u_i − b_i θ̇_i;
- a drive: the arm's input is τg = k (θm − θ) + d (θ̇m − θ̇) and the rotor
  B θ̈m = u_i − τg − b_i θ̇m (the gear linearised in contact: no dead zone).
"""
from __future__ import annotations

import numpy as np

from ..contract.signals import motor_outputs

__all__ = ["with_joints", "nonlinear_joint_effects"]


def nonlinear_joint_effects(params) -> tuple[str, ...]:
    """What of ``params``' joints a linear model leaves out, in words (empty: nothing).

    Parameters
    ----------
    params : ArmParameters
        The arm.

    Returns
    -------
    tuple of str
        One phrase per joint effect left out, e.g. ``"joint 1 dry friction (Coulomb 0.3
        N m, breakaway 0.4 N m)"``.
    """
    out = []
    for i, joint in enumerate(params.joints, start=1):
        if joint.static_friction > 0:
            out.append(f"joint {i} dry friction (Coulomb {joint.coulomb:g} N m, breakaway "
                       f"{joint.static_friction:g} N m)")
        if joint.backlash > 0:
            out.append(f"joint {i} backlash ({joint.backlash:g} rad)")
    return tuple(out)


def with_joints(arm, params):
    """The linear arm ``arm`` with ``params``' linear joint effects (module docstring).

    Parameters
    ----------
    arm : control.StateSpace
        A continuous linear arm without joint effects, D = 0: inputs ``tau1`` … ``tauN``
        (then any generalised forces, passed through), outputs including ``theta<i>`` and
        ``theta<i>_dot``.
    params : ArmParameters
        The arm whose joints are added.

    Returns
    -------
    control.StateSpace
        The same inputs (``tau<i>`` now the motor commands), the arm's outputs then
        `motor_outputs`, the arm's states then, per drive, ``motor<i>`` and
        ``motor<i>_dot``, and, per lag, ``tau<i>_applied``.
    """
    import control  # loaded by the linear verdicts that use it
    A, B, C = (np.asarray(m, dtype=float) for m in (arm.A, arm.B, arm.C))
    outs = list(arm.output_labels)
    N = len(params.joints)
    joints = range(N)
    theta = C[[outs.index(f"theta{i + 1}") for i in joints]]
    rate = C[[outs.index(f"theta{i + 1}_dot") for i in joints]]
    na, ni = A.shape[0], B.shape[1]
    drives = [i for i in joints if params.joints[i].has_drive]
    lags = [i for i in joints if params.joints[i].torque_time_constant > 0]
    nz = na + 2 * len(drives) + len(lags)
    # Row vectors over the state z (and the inputs) of the quantities the joints use.
    rotor = {i: np.eye(nz)[na + k] for k, i in enumerate(drives)}
    rotor_rate = {i: np.eye(nz)[na + len(drives) + k] for k, i in enumerate(drives)}
    motor_torque_z, motor_torque_c = np.zeros((N, nz)), np.zeros((N, ni))
    for i in joints:
        if i in lags:
            motor_torque_z[i, na + 2 * len(drives) + lags.index(i)] = 1.0
        else:
            motor_torque_c[i, i] = 1.0
    pad = lambda row: np.concatenate([row, np.zeros(nz - na)])  # noqa: E731
    Az, Bz = np.zeros((nz, nz)), np.zeros((nz, ni))
    Az[:na, :na] = A
    Bz[:na, N:] = B[:, N:]
    for i in joints:
        get = lambda name: getattr(params.joints[i], name)  # noqa: E731
        if i in drives:
            k, d, J, b = (get(n) for n in ("gear_stiffness", "gear_damping", "rotor_inertia",
                                           "viscous"))
            gear = (k * (rotor[i] - pad(theta[i])) + d * (rotor_rate[i] - pad(rate[i])))
            arm_z, arm_c = gear, np.zeros(ni)
            r = na + drives.index(i)
            Az[r] = rotor_rate[i]
            Az[r + len(drives)] = (motor_torque_z[i] - gear - b * rotor_rate[i]) / J
            Bz[r + len(drives)] = motor_torque_c[i] / J
        else:
            arm_z = motor_torque_z[i] - get("viscous") * pad(rate[i])
            arm_c = motor_torque_c[i]
        Az[:na] += np.outer(B[:, i], arm_z)
        Bz[:na] += np.outer(B[:, i], arm_c)
        if i in lags:
            r = na + 2 * len(drives) + lags.index(i)
            T = get("torque_time_constant")
            Az[r] = -motor_torque_z[i] / T
            Bz[r, i] = 1.0 / T
    Cz = np.hstack([C, np.zeros((C.shape[0], nz - na))])
    motors = [rotor[i] if i in drives else pad(theta[i]) for i in joints]
    motors += [rotor_rate[i] if i in drives else pad(rate[i]) for i in joints]
    states = list(arm.state_labels)
    states += [f"motor{i + 1}" for i in drives] + [f"motor{i + 1}_dot" for i in drives]
    states += [f"tau{i + 1}_applied" for i in lags]
    return control.ss(Az, Bz, np.vstack([Cz, motors]), np.zeros((C.shape[0] + 2 * N, ni)),
                      inputs=list(arm.input_labels), outputs=outs + list(motor_outputs(N)),
                      states=states, name=arm.name)
