"""The compiled dynamics of an N-link arm: the model packed for compiled code
(`layout`), the paper's and the exact kinematics (`linear`, `exact`), the equations of
motion and their RK4 integration for either (`motion`), the entry points Python calls
(`entries`) and small linear algebra (`linalg`)."""
from .entries import Kernels, kernels
from .layout import (LinkData, LinkPack, ModelData, Workspace, link_data, new_workspace,
                     pack_model, unpack_model, unpack_workspace)
from .linalg import (cholesky_factor_inplace, cholesky_solve_factored, cholesky_solve_inplace,
                     matrix_view, vector_view)
from .motion import (acceleration_into, bias_forces_into, coriolis_matrix_into, elastic_into,
                     mass_bias_into, mass_matrix_into, rhs_into, rk4_advance, tips_into)

__all__ = ["Kernels", "kernels", "LinkData", "LinkPack", "ModelData", "Workspace", "link_data",
           "new_workspace", "pack_model", "unpack_model", "unpack_workspace",
           "cholesky_factor_inplace", "cholesky_solve_factored", "cholesky_solve_inplace",
           "matrix_view", "vector_view", "acceleration_into", "bias_forces_into",
           "coriolis_matrix_into", "elastic_into", "mass_bias_into", "mass_matrix_into",
           "rhs_into", "rk4_advance", "tips_into"]
