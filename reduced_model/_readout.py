"""The reduced plant's modal coordinates as a sensor reads them: q, q̇ of its deflection
in the measurement basis (the laws' mode shapes), compiled for the plant and the loop.

Linear kinematics: the deflection is Σ φ q, so the measured q is the plant's own q, or
its projection on other mode shapes by a fixed matrix (`reduced_model._modes.projection`).
Exact kinematics: the centreline's transverse position y(s) is Σ φ q + Σ r_h Im g_h and
its tip slope sin β(L), not w'(L), so the measured q — the FE plant's mass-weighted
projection of the same centreline — is a fixed matrix (`reduced_model._inextensible.
readout_matrix`) times the features [q, Im g_h, sin β(L) − p(L)] of each link.  A plant
that reported its coordinates instead would feed the laws a q of another definition than
the FE arm's (they differ at third order in the deflection, enough for a PBC closed loop
from rest to follow the FE arm less closely than the paper's model does).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._exact_data import unpack_exact
from ._kernels import unpack_model

__all__ = ["modal_readout_into"]


@njit(cache=True, inline="always")
def _exact_link_features(e, dphi, dphi_tip, nl, c, readout, col, x, npl, q, qd):
    """Add one link's feature terms readout[:, col…] · z (and ż) to ``q`` (``qd``)."""
    nb = readout.shape[0]
    for k in range(nl):
        for i in range(nb):
            q[i] += readout[i, col + k] * x[c + k]
            qd[i] += readout[i, col + k] * x[npl + c + k]
    col += nl
    for h in range(e.N):
        p, pd = 0.0, 0.0
        for k in range(nl):
            p += dphi[k, h] * x[c + k]
            pd += dphi[k, h] * x[npl + c + k]
        u = 1.0 / (1.0 + p * p)
        s = np.sqrt(u)
        z = p * s - p  # Im g = sin β − p
        zd = (u * s - 1.0) * pd  # d(sin β)/dt = ṗ / (1 + p²)^{3/2}
        for i in range(nb):
            q[i] += readout[i, col + h] * z
            qd[i] += readout[i, col + h] * zd
    col += e.N
    p, pd = 0.0, 0.0
    for k in range(nl):
        p += dphi_tip[k] * x[c + k]
        pd += dphi_tip[k] * x[npl + c + k]
    u = 1.0 / (1.0 + p * p)
    s = np.sqrt(u)
    for i in range(nb):
        q[i] += readout[i, col] * (p * s - p)
        qd[i] += readout[i, col] * (u * s - 1.0) * pd
    return col + 1


@njit(cache=True)
def modal_readout_into(ints, reals, readout, x, q, qd):
    """q, q̇ of the state ``x`` = [Q, Q̇] of the packed model (``ints``, ``reals``) in the
    measurement basis, into ``q`` and ``qd``: ``readout`` is the map from the plant's
    modal coordinates (0 × 0: the same basis) or, for exact kinematics, from its
    deflection features (module docstring)."""
    d = unpack_model(ints, reals)
    npl = x.shape[0] // 2
    if d.exact.N == 0:
        if readout.shape[0] == 0:
            for i in range(npl - 2):
                q[i] = x[2 + i]
                qd[i] = x[npl + 2 + i]
            return
        for i in range(readout.shape[0]):
            a = 0.0
            b = 0.0
            for j in range(npl - 2):
                a += readout[i, j] * x[2 + j]
                b += readout[i, j] * x[npl + 2 + j]
            q[i] = a
            qd[i] = b
        return
    e = unpack_exact(d.exact)
    for i in range(readout.shape[0]):
        q[i] = 0.0
        qd[i] = 0.0
    col = _exact_link_features(e, e.dphi1, e.dphi1_tip, e.n1, 2, readout, 0, x, npl, q, qd)
    _exact_link_features(e, e.dphi2, e.dphi2_tip, e.n2, 2 + e.n1, readout, col, x, npl, q, qd)
