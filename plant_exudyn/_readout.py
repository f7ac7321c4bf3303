"""The truth plant's readout, compiled: the truth vector (θ, projected q, rates, tips,
tip deflections, projection residuals) from Exudyn's ODE2 coordinates in one call, for
an arm of N links, each flexible (a `LinkField`) or rigid (no modal coordinates, no
deflection)."""
from __future__ import annotations

import numpy as np
from numba import njit, typed, types
from numba.experimental import structref

from ._fields import link_readout

__all__ = ["Readout", "new_readout", "readout_into", "link_arrays"]

_V, _I = types.Array(types.float64, 1, "C"), types.Array(types.int64, 1, "C")
_M, _MI = types.Array(types.float64, 2, "C"), types.Array(types.int64, 2, "C")

#: Tangent at a link's tip: the slope of an ANCF node, or a rotation coordinate.
SLOPE, ROTATION = 0, 1


class _Struct(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class _LinkType(_Struct):
    pass


@structref.register
class _ReadoutType(_Struct):
    pass


class LinkArrays(structref.StructRefProxy):
    """One flexible link's `LinkField` arrays (`LinkField.compiled`)."""


class Readout(structref.StructRefProxy):
    """What `readout_into` reads the truth from Exudyn's coordinates with: the joints'
    and tips' indices and reference values, and each flexible link's `LinkField` arrays
    (one structure passed by reference: a call costs ~1 µs, 27 separate arrays cost ~5)."""


structref.define_boxing(_LinkType, LinkArrays)
structref.define_boxing(_ReadoutType, Readout)
_LINK = _LinkType((("idx", _MI), ("ref", _M), ("hub_idx", _I), ("hub_ref", _V), ("d", _V),
                   ("dd", _V), ("projector", _M), ("H_quad", _M), ("phi_T", _M),
                   ("rho_w", _V)))
_READOUT = _ReadoutType((("ancf", types.boolean), ("hub_idx", _I), ("hub_ref", _V),
                         ("tangent_kind", _I), ("tangent_idx", _MI), ("tangent_ref", _M),
                         ("tip_idx", _MI), ("tip_ref", _M), ("tip_arm", _M),
                         ("field_of", _I), ("fields", types.ListType(_LINK))))


@njit(cache=True)
def _new_link(idx, ref, hub_idx, hub_ref, d, dd, projector, H_quad, phi_T, rho_w):
    f = structref.new(_LINK)
    f.idx, f.ref, f.hub_idx, f.hub_ref, f.d, f.dd = idx, ref, hub_idx, hub_ref, d, dd
    f.projector, f.H_quad, f.phi_T, f.rho_w = projector, H_quad, phi_T, rho_w
    return f


@njit(cache=True)
def _no_links():
    return typed.List.empty_list(_LINK)


@njit(cache=True)
def _add_link(links, link):
    links.append(link)


def link_arrays(fields) -> typed.List:
    """The compiled arrays of the `LinkField` s ``fields`` (shared, not copied).  The list
    is made and filled by compiled (cached) functions: its own methods, called from
    Python, compile anew in every process (0.18 s)."""
    out = _no_links()
    for f in fields:
        _add_link(out, _new_link(*f.compiled()))
    return out


@njit(cache=True)
def new_readout(ancf, hub_idx, hub_ref, tangent_kind, tangent_idx, tangent_ref, tip_idx,
                tip_ref, tip_arm, field_of, fields):
    """A `Readout` of these arrays (shared, not copied).

    Per joint i: ``hub_idx``/``hub_ref`` its hub's rotation coordinate and reference
    angle; ``tangent_*`` link i−1's tip tangent (row 0 unused): `SLOPE` (an ANCF node's
    slope coordinates) or `ROTATION` (a rotation coordinate, first column).  Per link:
    ``tip_idx`` the x, y and rotation (−1: none) coordinates of the node its tip is read
    from, ``tip_ref`` that node's reference position, ``tip_arm`` the tip's offset from it
    at the reference; ``field_of`` its entry in ``fields`` (−1: rigid)."""
    r = structref.new(_READOUT)
    r.ancf, r.hub_idx, r.hub_ref = ancf, hub_idx, hub_ref
    r.tangent_kind, r.tangent_idx, r.tangent_ref = tangent_kind, tangent_idx, tangent_ref
    r.tip_idx, r.tip_ref, r.tip_arm = tip_idx, tip_ref, tip_arm
    r.field_of, r.fields = field_of, fields
    return r


@njit(cache=True)
def readout_into(r, u, v, out):
    """The truth vector from Exudyn's ODE2 coordinates ``u`` and rates ``v``, in one
    compiled call (`LinkField` written out; the motors are read apart)."""
    N = r.hub_idx.shape[0]
    m = N
    for i in range(N):
        if r.field_of[i] >= 0:
            m += r.fields[r.field_of[i]].projector.shape[0]
    hub_idx, hub_ref = r.hub_idx, r.hub_ref
    root = hub_ref[0] + u[hub_idx[0]]  # link i−1's root frame angle
    out[0] = root
    out[m] = v[hub_idx[0]]
    for i in range(1, N):
        hub = hub_ref[i] + u[hub_idx[i]]
        ti, tr = r.tangent_idx[i], r.tangent_ref[i]
        if r.tangent_kind[i] == SLOPE:
            sx, sy = tr[0] + u[ti[0]], tr[1] + u[ti[1]]
            sxd, syd = v[ti[0]], v[ti[1]]
            c, s = np.cos(root), np.sin(root)
            # Tangent angle = root angle + (small) angle of the slope in its frame: continuous.
            tangent = root + np.arctan2(-s * sx + c * sy, c * sx + s * sy)
            tangent_rate = (sx * syd - sy * sxd) / (sx * sx + sy * sy)
        else:
            tangent = tr[0] + u[ti[0]]
            tangent_rate = v[ti[0]]
        out[i] = hub - tangent
        out[m + i] = v[hub_idx[i]] - tangent_rate
        root = hub
    e = 2 * m
    for k in range(N):
        idx = r.tip_idx[k]
        if idx[2] < 0:
            for j in range(2):
                out[e + 2 * k + j] = r.tip_ref[k, j] + u[idx[j]]
        else:  # a point on a rigid body
            c, s = np.cos(u[idx[2]]), np.sin(u[idx[2]])
            ax, ay = r.tip_arm[k, 0], r.tip_arm[k, 1]
            out[e + 2 * k] = r.tip_ref[k, 0] + u[idx[0]] + (c * ax - s * ay)
            out[e + 2 * k + 1] = r.tip_ref[k, 1] + u[idx[1]] + (s * ax + c * ay)
    o = N
    for k in range(N):
        if r.field_of[k] < 0:
            out[e + 2 * N + k], out[e + 3 * N + k] = 0.0, 0.0
            continue
        f = r.fields[r.field_of[k]]
        n = f.projector.shape[0]
        out[e + 2 * N + k], out[e + 3 * N + k] = link_readout(
            u, v, r.ancf, f.idx, f.ref, f.hub_idx, f.hub_ref, f.d, f.dd, f.projector,
            f.H_quad, f.phi_T, f.rho_w, out[o:o + n], out[m + o:m + o + n])
        o += n
