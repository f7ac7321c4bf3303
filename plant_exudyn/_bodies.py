"""The arm's bodies in Exudyn, link by link (`_build.build_arm` drives it): flexible links
(a hub and a beam, the next motor's stator at the tip, or the payload), rigid links (one
rigid body each), and the joints between them.

A rigid link is one ``ObjectRigidBody2D`` whose node sits at its centre of mass (Exudyn's
2D rigid body then has the constant mass matrix diag(m, m, J), which the exact hold
relies on); everything rigidly on the link is part of it: its hub (mass and inertia at
the root), its distributed mass ρL, and at its tip the next motor's stator or, on the
last link, the payload.  Its joints act at the root and tip points through body markers
(the constraint Jacobian's rotation column then turns with the body: `_hold`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import exudyn as exu
import exudyn.beams
import numpy as np
from exudyn.itemInterface import (MarkerBodyPosition, MarkerBodyRigid, MarkerNodePosition,
                                  MarkerNodeRigid, NodeRigidBody2D, ObjectANCFCable2D,
                                  ObjectBeamGeometricallyExact2D, ObjectJointGeneric,
                                  ObjectJointRevolute2D, ObjectMassPoint2D,
                                  ObjectRigidBody2D)

from ._mesh import Mesh

__all__ = ["ArmBuilder", "LinkNodes", "RigidLink", "beam_template"]

_CLAMP = [1, 1, 0, 0, 0, 1]  # x, y and the in-plane rotation


@dataclass
class LinkNodes:
    """Nodes of one flexible link, root to tip, with their reference arc length [m]."""

    nodes: list[int]
    s: np.ndarray
    coords: np.ndarray = field(default=None)  # (n_nodes, k) ODE2 indices of each node


@dataclass
class RigidLink:
    """A rigid link's body: its node (at the body's centre of mass), the object, the
    centre's distance from the link's root along the link and the link's length [m]."""

    node: int
    body: int
    centre: float
    length: float


def _rot3(a: float) -> list[list[float]]:
    c, s = np.cos(a), np.sin(a)
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


def beam_template(mesh: Mesh, *, rho: float, EI: float, damping: float):
    """The Exudyn beam element (template for `GenerateBeamElementsAlongLine`) of a link.

    ``damping`` is the Kelvin–Voigt bending damping d [N m² s] (`ArmParameters`); the
    material's retardation time β = d / EI damps every strain alike — bending (d), axial
    (β EA) and, for the geometrically exact beam, shear (β GA) — so every mode of the
    link, axial ones included, has the damping ratio ζ = π f β (stiffness-proportional).
    Bending damping alone left the axial modes (0.5–26 kHz) undamped."""
    ea, beta = mesh.axial_stiffness, damping / EI
    if mesh.element == "ancf":
        return ObjectANCFCable2D(massPerLength=rho, bendingStiffness=EI, axialStiffness=ea,
                                 bendingDamping=damping, axialDamping=beta * ea)
    ga = 0.4 * ea
    return ObjectBeamGeometricallyExact2D(
        massPerLength=rho, crossSectionInertia=rho * EI / ea, bendingStiffness=EI,
        axialStiffness=ea, shearStiffness=ga, bendingDamping=damping,
        axialDamping=beta * ea, shearDamping=beta * ga)


def rigid_body(params, i: int, root_mass: float = 0.0) -> tuple[float, float, float]:
    """(mass [kg], centre of mass from the root [m], inertia about it [kg m²]) of rigid
    link ``i`` (from 0) with its hub, its distributed mass and what sits at its tip (the
    next stator, or the payload) (module docstring); ``root_mass``: a point mass [kg]
    more at its root (the stator of a flexible link i−1 without stator inertia)."""
    link = params.links[i]
    L, rho_L = link.length, link.mass_per_length * link.length
    last = i == params.n_links - 1
    root_mass = link.hub_mass + root_mass
    tip_mass = params.payload.mass if last else link.stator_mass
    tip_inertia = params.payload.inertia if last else link.stator_inertia
    mass = root_mass + rho_L + tip_mass
    centre = (rho_L * L / 2 + tip_mass * L) / mass
    inertia = (link.hub_inertia + tip_inertia + root_mass * centre**2
               + rho_L * (L * L / 12 + (L / 2 - centre)**2) + tip_mass * (L - centre)**2)
    return mass, centre, inertia


class ArmBuilder:
    """Adds the arm's links to ``mbs`` one after the other (`flexible_link`,
    `rigid_link`), keeping what the rest of the build needs: each joint's hub, base
    stator and reference angle, the torque markers, the bodies with mass."""

    def __init__(self, mbs, params, mesh: Mesh, *, ground: int, lock_joints: bool) -> None:
        self.mbs, self.p, self.mesh = mbs, params, mesh
        self.ground, self.lock = ground, lock_joints
        self.links: list = []
        self.hubs: list[int] = []
        self.hub_angles: list[float] = []
        self.stators: list = [None]
        self.hub_markers: list[int] = []  # τi acts here
        self.tip_markers: list[int] = []  # −τ(i+1) acts here (link i's tip, rigid marker)
        self.massive: list[int] = []  # every object with mass (gravity)
        self.payload: int | None = None
        self.tip_position: np.ndarray | None = None
        self._tip_point = None  # makes a position marker at the last link's tip
        self._lumped = 0.0  # a stator's point mass at the next joint (no stator inertia)

    # --- primitives -------------------------------------------------------------------------
    def _node(self, pos, angle) -> int:
        return self.mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[pos[0], pos[1], angle]))

    def _body_on(self, node, mass, inertia) -> None:
        if mass > 0.0 or inertia > 0.0:
            self.massive.append(self.mbs.AddObject(
                ObjectRigidBody2D(nodeNumber=node, mass=mass, inertia=inertia)))

    def _clamp(self, marker0, node1=None, relative_angle=0.0, *, body=None,
               offset=0.0) -> None:
        """Fix node ``node1`` (or the point ``offset`` along rigid ``body``) to
        ``marker0`` in position and in-plane rotation, keeping the relative angle
        ``relative_angle`` it has in the reference layout."""
        frame = exu.HT(rotation=_rot3(-relative_angle), translation=[offset, 0.0, 0.0])
        marker1 = self.mbs.AddMarker(MarkerNodeRigid(nodeNumber=node1, localHT=frame)
                                     if body is None else
                                     MarkerBodyRigid(bodyNumber=body, localHT=frame))
        self.mbs.AddObject(ObjectJointGeneric(markerNumbers=[marker0, marker1],
                                              constrainedAxes=_CLAMP))

    def _join(self, i: int, relative: float, *, node=None, body=None, offset=0.0) -> None:
        """Joint ``i``: link i's root (node ``node``, or the point ``offset`` along rigid
        ``body``) turning on the ground (i = 0) or at link i−1's tip, or clamped there."""
        mbs = self.mbs
        if i == 0:
            base_rigid = mbs.AddMarker(MarkerBodyRigid(bodyNumber=self.ground,
                                                       localPosition=[0, 0, 0]))
        else:
            base_rigid = self.tip_markers[-1]
        if self.lock:
            self._clamp(base_rigid, node, relative, body=body, offset=offset)
            return
        base = (mbs.AddMarker(MarkerBodyPosition(bodyNumber=self.ground, localPosition=[0, 0, 0]))
                if i == 0 else self._tip_point())
        moving = (mbs.AddMarker(MarkerNodePosition(nodeNumber=node)) if body is None else
                  mbs.AddMarker(MarkerBodyPosition(bodyNumber=body,
                                                   localPosition=[offset, 0.0, 0.0])))
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[base, moving]))

    # --- links -------------------------------------------------------------------------------
    def flexible_link(self, i: int, root, angle: float, relative: float, n_el: int) -> None:
        """Link ``i``: its hub at ``root`` turned to ``angle`` (``relative`` to link
        i−1's tip), joint i, the beam of ``n_el`` elements, then its tip's stator or the
        payload."""
        mbs, p, link = self.mbs, self.p, self.p.links[i]
        last = i == p.n_links - 1
        tip = root + link.length * np.array([np.cos(angle), np.sin(angle)])
        hub = self._node(root, angle)
        m_hub = mbs.AddMarker(MarkerNodeRigid(nodeNumber=hub))
        self._join(i, relative, node=hub)
        if i > 0:
            self._body_on(hub, link.hub_mass + self._lumped, link.hub_inertia)
        template = beam_template(self.mesh, rho=link.mass_per_length,
                                 EI=link.bending_stiffness, damping=link.bending_damping)
        ancf = self.mesh.element == "ancf"
        gen = exudyn.beams.GenerateBeamElementsAlongLine(
            mbs, [*root, 0], [*tip, 0], n_el, template,
            **({} if ancf else {"nodeNumberStart": hub}))  # GE: the hub is the root node
        nodes = list(gen["nodes"])
        if ancf:
            self._clamp(m_hub, nodes[0])
        self.massive.extend(gen["elements"])
        if i == 0:
            self._body_on(hub, link.hub_mass, link.hub_inertia)
        if not last:
            m_tip = mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[-1]))
            stator, self._lumped = None, link.stator_mass
            if link.stator_inertia > 0.0:
                stator, self._lumped = self._node(tip, angle), 0.0
                self._body_on(stator, link.stator_mass, link.stator_inertia)
                self._clamp(m_tip, stator)
            # a point mass at the joint without inertia moves with the next root: lumped there
            self.stators.append(stator)
            self.tip_markers.append(m_tip)
        elif ancf:
            if p.payload.inertia > 0.0:
                self.payload = self._node(tip, angle)
                self._body_on(self.payload, p.payload.mass, p.payload.inertia)
                self._clamp(mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[-1])), self.payload)
            elif p.payload.mass > 0.0:  # a point mass: on the tip node itself
                self.massive.append(mbs.AddObject(
                    ObjectMassPoint2D(nodeNumber=nodes[-1], mass=p.payload.mass)))
        else:
            self.payload = nodes[-1]
            self._body_on(self.payload, p.payload.mass, p.payload.inertia)
        tip_node = nodes[-1] if self.payload is None else self.payload
        self._tip_point = lambda: mbs.AddMarker(MarkerNodePosition(nodeNumber=tip_node))
        self._finish(LinkNodes(nodes, np.linspace(0.0, link.length, n_el + 1)), hub, m_hub,
                     angle, tip)

    def rigid_link(self, i: int, root, angle: float, relative: float) -> None:
        """Link ``i``: one rigid body (module docstring) from ``root`` at ``angle``
        (``relative`` to link i−1's tip), and joint i."""
        mbs, link = self.mbs, self.p.links[i]
        last = i == self.p.n_links - 1
        mass, centre, inertia = rigid_body(self.p, i, self._lumped)
        self._lumped = 0.0
        L = link.length
        e = np.array([np.cos(angle), np.sin(angle)])
        node = self._node(root + centre * e, angle)
        body = mbs.AddObject(ObjectRigidBody2D(nodeNumber=node, mass=mass, inertia=inertia))
        self.massive.append(body)
        m_hub = mbs.AddMarker(MarkerBodyRigid(bodyNumber=body, localPosition=[-centre, 0, 0]))
        self._join(i, relative, body=body, offset=-centre)
        if not last:
            self.stators.append(node)
            self.tip_markers.append(mbs.AddMarker(MarkerBodyRigid(
                bodyNumber=body, localPosition=[L - centre, 0, 0])))
        self._tip_point = lambda: mbs.AddMarker(MarkerBodyPosition(
            bodyNumber=body, localPosition=[L - centre, 0.0, 0.0]))
        self._finish(RigidLink(node, body, centre, L), node, m_hub, angle, root + L * e)

    def _finish(self, link, hub: int, m_hub: int, angle: float, tip) -> None:
        self.links.append(link)
        self.hubs.append(hub)
        self.hub_markers.append(m_hub)
        self.hub_angles.append(angle)
        self.tip_position = tip

    def tip_position_marker(self) -> int:
        """A new position marker at the last link's tip (the payload)."""
        return self._tip_point()
