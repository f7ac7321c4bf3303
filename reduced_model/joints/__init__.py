"""The joints beyond the paper's ideal ones: friction with stiction, drives with backlash
and the current loops' lag, compiled for the reduced plant (`reduced_model.joints.kernels`)
and added exactly to linear models (`reduced_model.joints.linear`)."""
from .kernels import (PARAMETERS, advance_joints_exact, advance_joints_linear, joints_active,
                      lag_step, motor_state_into, new_joint_buffers, reset_joints)
from .linear import nonlinear_joint_effects, with_joints

__all__ = ["PARAMETERS", "advance_joints_exact", "advance_joints_linear", "joints_active",
           "lag_step", "motor_state_into", "new_joint_buffers", "reset_joints",
           "nonlinear_joint_effects", "with_joints"]
