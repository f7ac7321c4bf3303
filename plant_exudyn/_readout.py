"""The truth plant's readout, compiled: the truth vector (θ, projected q, rates, tips,
tip deflections, projection residuals) from Exudyn's ODE2 coordinates in one call."""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.experimental import structref

from ._fields import link_readout

__all__ = ["Readout", "new_readout", "readout_into"]

_V, _I = types.Array(types.float64, 1, "C"), types.Array(types.int64, 1, "C")
_M, _MI = types.Array(types.float64, 2, "C"), types.Array(types.int64, 2, "C")
_LINK = (("idx", _MI), ("ref", _M), ("hub_idx", _I), ("hub_ref", _V), ("d", _V), ("dd", _V),
         ("projector", _M), ("H_quad", _M), ("phi_T", _M), ("rho_w", _V))  # `LinkField.compiled`


@structref.register
class _ReadoutType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Readout(structref.StructRefProxy):
    """What `readout_into` reads the truth from Exudyn's coordinates with: the joints'
    and tips' indices and reference values, and each link's `LinkField` arrays (one
    structure passed by reference: a call costs ~1 µs, 27 separate arrays cost ~5)."""


structref.define_boxing(_ReadoutType, Readout)
_READOUT = _ReadoutType((("ancf", types.boolean), ("jidx", _I), ("jref", _V),
                         ("tip_idx", _MI), ("tip_ref", _M),
                         *((f"{name}1", typ) for name, typ in _LINK),
                         *((f"{name}2", typ) for name, typ in _LINK)))


@njit(cache=True)
def new_readout(ancf, jidx, jref, tip_idx, tip_ref,
                idx1, ref1, hub_idx1, hub_ref1, d1, dd1, projector1, H_quad1, phi_T1, rho_w1,
                idx2, ref2, hub_idx2, hub_ref2, d2, dd2, projector2, H_quad2, phi_T2, rho_w2):
    """A `Readout` of these arrays (shared, not copied)."""
    r = structref.new(_READOUT)
    r.ancf, r.jidx, r.jref, r.tip_idx, r.tip_ref = ancf, jidx, jref, tip_idx, tip_ref
    r.idx1, r.ref1, r.hub_idx1, r.hub_ref1, r.d1, r.dd1 = idx1, ref1, hub_idx1, hub_ref1, d1, dd1
    r.projector1, r.H_quad1, r.phi_T1, r.rho_w1 = projector1, H_quad1, phi_T1, rho_w1
    r.idx2, r.ref2, r.hub_idx2, r.hub_ref2, r.d2, r.dd2 = idx2, ref2, hub_idx2, hub_ref2, d2, dd2
    r.projector2, r.H_quad2, r.phi_T2, r.rho_w2 = projector2, H_quad2, phi_T2, rho_w2
    return r


@njit(cache=True)
def readout_into(r, u, v, out):
    """The truth vector from Exudyn's ODE2 coordinates ``u`` and rates ``v``, in one
    compiled call (`ExudynPlant._joints` and `LinkField` written out)."""
    n1, n2 = r.projector1.shape[0], r.projector2.shape[0]
    m = 2 + n1 + n2
    jidx, jref = r.jidx, r.jref
    th1 = jref[0] + u[jidx[0]]
    hub2 = jref[1] + u[jidx[1]]
    if r.ancf:
        sx, sy = jref[2] + u[jidx[2]], jref[3] + u[jidx[3]]
        sxd, syd = v[jidx[2]], v[jidx[3]]
        c, s = np.cos(th1), np.sin(th1)
        tangent = th1 + np.arctan2(-s * sx + c * sy, c * sx + s * sy)
        tangent_rate = (sx * syd - sy * sxd) / (sx * sx + sy * sy)
    else:
        tangent = jref[2] + u[jidx[2]]
        tangent_rate = v[jidx[2]]
    out[0], out[1] = th1, hub2 - tangent
    out[m], out[m + 1] = v[jidx[0]], v[jidx[1]] - tangent_rate
    e = 2 * m
    for k in range(2):
        for j in range(2):
            out[e + 2 * k + j] = r.tip_ref[k, j] + u[r.tip_idx[k, j]]
    out[e + 4], out[e + 6] = link_readout(u, v, r.ancf, r.idx1, r.ref1, r.hub_idx1, r.hub_ref1,
                                          r.d1, r.dd1, r.projector1, r.H_quad1, r.phi_T1,
                                          r.rho_w1, out[2:2 + n1], out[m + 2:m + 2 + n1])
    out[e + 5], out[e + 7] = link_readout(u, v, r.ancf, r.idx2, r.ref2, r.hub_idx2, r.hub_ref2,
                                          r.d2, r.dd2, r.projector2, r.H_quad2, r.phi_T2,
                                          r.rho_w2, out[2 + n1:m], out[m + 2 + n1:2 * m])
