"""Where the FE arm's nodes go for a configuration Q = [θ, q] of the reduced model: each
flexible link on the inextensible curve of its modal deflection, each rigid link straight,
everything rigidly attached placed with its link."""
from __future__ import annotations

import numpy as np
from scipy.integrate import cumulative_trapezoid

from reduced_model import LinkModes

from ._bodies import LinkNodes

__all__ = ["node_displacements"]


def _curve(modes: LinkModes, q, s):
    """Inextensible curve with slope angle β = atan(w'): (x, y, β) at arc lengths s."""
    fine = np.linspace(0.0, modes.L, 4001)
    beta = np.arctan(modes.dphi(fine).T @ q)
    x = cumulative_trapezoid(np.cos(beta), fine, initial=0.0)
    y = cumulative_trapezoid(np.sin(beta), fine, initial=0.0)
    return np.interp(s, fine, x), np.interp(s, fine, y), np.arctan(modes.dphi(s).T @ q)


def node_displacements(system, modal_basis, Q: np.ndarray) -> np.ndarray:
    """The ODE2 displacement vector of the `ArmSystem` ``system`` placing every node for
    the configuration ``Q`` = [θ, q] (q in ``modal_basis``, one `LinkModes` per link)."""
    mbs = system.mbs
    sd = mbs.systemData
    N = len(system.links)
    u = np.zeros(sd.ODE2Size())

    def place(node, pos, angle_or_slope):
        idx = sd.GetNodeLTGODE2(node)
        ref = np.array(mbs.GetNodeParameter(node, "referenceCoordinates"), float)
        u[idx] = np.concatenate([pos, np.atleast_1d(angle_or_slope)]) - ref

    origin, tangent, c = np.zeros(2), 0.0, N
    hub_angles = []
    for i, link in enumerate(system.links):
        frame_angle = tangent + Q[i]
        hub_angles.append(frame_angle)
        cos, sin = np.cos(frame_angle), np.sin(frame_angle)
        if isinstance(link, LinkNodes):
            n = modal_basis[i].n
            place(system.hubs[i], origin, frame_angle)
            x, y, beta = _curve(modal_basis[i], Q[c:c + n], link.s)
            c += n
            pos = origin + np.column_stack([cos * x - sin * y, sin * x + cos * y])
            for k, node in enumerate(link.nodes):
                ang = frame_angle + beta[k]
                place(node, pos[k], [np.cos(ang), np.sin(ang)] if system.element == "ancf"
                      else ang)
            origin, tangent = pos[-1], frame_angle + beta[-1]
        else:
            e = np.array([cos, sin])
            place(link.node, origin + link.centre * e, frame_angle)
            origin, tangent = origin + link.length * e, frame_angle
        stator = system.stators[i + 1] if i + 1 < N else system.payload
        if stator is not None and isinstance(link, LinkNodes):
            place(stator, origin, tangent)
    for rotor, hub_angle in zip(system.joints.rotors, hub_angles):
        if rotor is not None:  # on its hub: the gear unloaded
            u[sd.GetNodeLTGODE2(rotor)[0]] = hub_angle - mbs.GetNodeParameter(
                rotor, "referenceCoordinates")[0]
    return u
