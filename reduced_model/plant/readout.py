"""The reduced plant's modal coordinates as a sensor reads them: q, q̇ of its deflection
in the measurement basis (the laws' mode shapes), compiled for the plant's kernel.

Linear kinematics: the deflection is Σ φ q, so the measured q is the plant's own q, or
its projection on other mode shapes by a fixed matrix (`reduced_model.shapes.projection`).
Exact kinematics: the centreline's transverse position y(s) is Σ φ q + Σ r_h Im g_h and
its tip slope sin β(L), not w'(L), so the measured q — the FE plant's mass-weighted
projection of the same centreline — is a fixed matrix (`reduced_model.shapes.
readout_matrix`) times the features [q, Im g_h, sin β(L) − p(L)] of each flexible link.
A plant that reported its coordinates instead would feed the laws a q of another
definition than the FE arm's (they differ at third order in the deflection, enough for a
PBC closed loop from rest to follow the FE arm less closely than the paper's model does).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..dynamics import link_data

__all__ = ["modal_readout_into"]


@njit(cache=True, forceinline=True)
def _exact_link_features(ld, readout, col, x, npl, q, qd):
    """Add one link's feature terms readout[:, col…] · z (and ż) to ``q`` (``qd``)."""
    nb = readout.shape[0]
    nl, c = ld.n, ld.c
    for k in range(nl):
        for i in range(nb):
            q[i] += readout[i, col + k] * x[c + k]
            qd[i] += readout[i, col + k] * x[npl + c + k]
    col += nl
    for h in range(ld.nodes):
        p, pd = 0.0, 0.0
        for k in range(nl):
            p += ld.dphi[k, h] * x[c + k]
            pd += ld.dphi[k, h] * x[npl + c + k]
        u = 1.0 / (1.0 + p * p)
        s = np.sqrt(u)
        z = p * s - p  # Im g = sin β − p
        zd = (u * s - 1.0) * pd  # d(sin β)/dt = ṗ / (1 + p²)^{3/2}
        for i in range(nb):
            q[i] += readout[i, col + h] * z
            qd[i] += readout[i, col + h] * zd
    col += ld.nodes
    p, pd = 0.0, 0.0
    for k in range(nl):
        p += ld.dphi_tip[k] * x[c + k]
        pd += ld.dphi_tip[k] * x[npl + c + k]
    u = 1.0 / (1.0 + p * p)
    s = np.sqrt(u)
    for i in range(nb):
        q[i] += readout[i, col] * (p * s - p)
        qd[i] += readout[i, col] * (u * s - 1.0) * pd
    return col + 1


@njit(cache=True, inline="always")
def modal_readout_into(d, readout, x, q, qd, exact):
    """q, q̇ of the state ``x`` = [Q, Q̇] of the model ``d`` in the measurement basis, into
    ``q`` and ``qd``: ``readout`` is the map from the plant's modal coordinates (0 × 0:
    the same basis) or, for exact kinematics, from its deflection features (module
    docstring)."""
    npl = x.shape[0] // 2
    N = d.links
    if not exact:
        if readout.shape[0] == 0:
            for i in range(npl - N):
                q[i] = x[N + i]
                qd[i] = x[npl + N + i]
            return
        for i in range(readout.shape[0]):
            a = 0.0
            b = 0.0
            for j in range(npl - N):
                a += readout[i, j] * x[N + j]
                b += readout[i, j] * x[npl + N + j]
            q[i] = a
            qd[i] = b
        return
    for i in range(readout.shape[0]):
        q[i] = 0.0
        qd[i] = 0.0
    col = 0
    for link in range(N):
        ld = link_data(d, link)
        if ld.n:
            col = _exact_link_features(ld, readout, col, x, npl, q, qd)
