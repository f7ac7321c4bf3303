"""Cholesky factorisation and solves of small symmetric positive-definite matrices, in
place and allocation-free, for compiled code (the mass matrix of eq. 2, the EKF's
innovation covariance)."""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["cholesky_factor_inplace", "cholesky_solve_factored", "cholesky_solve_inplace"]


@njit(cache=True, inline="always")
def cholesky_factor_inplace(M):
    """Overwrite symmetric positive definite M by its lower Cholesky factor L, with
    1/L_jj on the diagonal (for `cholesky_solve_factored`).  False if M is not
    positive definite."""
    n = M.shape[0]
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= M[j, k] * M[j, k]
        if not s > 0.0:
            return False
        inv = 1.0 / np.sqrt(s)
        M[j, j] = inv
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= M[i, k] * M[j, k]
            M[i, j] = s * inv
    return True


@njit(cache=True, inline="always")
def cholesky_solve_factored(L, b):
    """Solve L Lᵀ y = b in place (``b`` becomes y), L from `cholesky_factor_inplace`."""
    n = L.shape[0]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * b[k]
        b[i] = s * L[i, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= L[k, i] * b[k]
        b[i] = s * L[i, i]


@njit(cache=True, inline="always")
def cholesky_solve_inplace(M, b):
    """Solve M y = b for symmetric positive definite M; M is overwritten by its factor,
    b by y.  False if M is not positive definite."""
    if not cholesky_factor_inplace(M):
        return False
    cholesky_solve_factored(M, b)
    return True
