"""Build the two-link arm as an Exudyn flexible multibody system from `ArmParameters`.

Bodies: hub 1 (revolute to ground, torque τ1), link 1 clamped to hub 1, hub 2 (the motor-2
rotor, revolute at the link-1 tip, torque τ2 with the reaction −τ2 on the link-1 tip),
the optional stator rigidly at the link-1 tip, link 2 clamped to hub 2, payload rigidly at
the link-2 tip, and the joints' friction and drives (`_drives`).  Horizontal plane, no
gravity.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import exudyn as exu
import exudyn.beams
import numpy as np
from exudyn.itemInterface import (
    LoadForceVector, LoadTorqueVector, MarkerBodyPosition, MarkerBodyRigid, MarkerNodePosition, MarkerNodeRigid,
    NodeRigidBody2D, ObjectANCFCable2D, ObjectBeamGeometricallyExact2D, ObjectGround,
    ObjectJointGeneric, ObjectJointRevolute2D, ObjectRigidBody2D,
)

from reduced_model import ArmParameters

from ._drives import Joints, add_joints
from ._mesh import Mesh

__all__ = ["ArmSystem", "build_arm", "beam_template", "simulation_settings"]

_CLAMP = [1, 1, 0, 0, 0, 1]  # x, y and the in-plane rotation


@dataclass
class LinkNodes:
    """Nodes of one link, root to tip, with their reference arc length [m]."""

    nodes: list[int]
    s: np.ndarray
    coords: np.ndarray = field(default=None)  # (n_nodes, k) ODE2 indices of each node


@dataclass
class ArmSystem:
    """An assembled Exudyn system of the arm and the handles the plant needs
    (`build_arm` makes it).

    Parameters
    ----------
    SC, mbs : exudyn SystemContainer and MainSystem
        The system, assembled.
    element : str
        The beam element ("ancf" or "geometrically_exact").
    links : (LinkNodes, LinkNodes)
        Each link's nodes, root to tip, with their arc length.
    hub1, hub2 : int
        The hubs' node numbers.
    stator : int or None
        The rigid body at the link-1 tip (only with stator inertia).
    payload : int or None
        The rigid body at the link-2 tip (the last beam node for GE beams).
    loads : (int, int, int)
        The loads τ1 on hub 1, τ2 on hub 2 and −τ2 on the link-1 tip.
    load_markers : (int, int, int)
        Their markers.
    tip_load : int
        The force on the payload (the link-2 tip), base frame.
    rigid_nodes : list of int
        Every NodeRigidBody2D, for initial conditions.
    joints : Joints
        Friction, drives, and the loads each motor torque sets.
    """

    SC: exu.SystemContainer
    mbs: exu.MainSystem
    element: str
    links: tuple[LinkNodes, LinkNodes]
    hub1: int
    hub2: int
    stator: int | None
    payload: int | None
    loads: tuple[int, int, int]
    load_markers: tuple[int, int, int]
    tip_load: int
    rigid_nodes: list[int]
    joints: Joints


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


def build_arm(params: ArmParameters, mesh: Mesh = Mesh(), *, theta=(0.0, 0.0),
              lock_joints: bool = False, step: float | None = None) -> ArmSystem:
    """Create and assemble the arm with links laid out straight at joint angles ``theta``.

    Parameters
    ----------
    params : ArmParameters
        The arm.
    mesh : Mesh
        The beam element and elements per link (default ANCF, 4 per link).
    theta : (float, float)
        Joint angles [rad] of the straight reference configuration.
    lock_joints : bool
        Replace both revolute joints by clamps (for locked-joint modal analysis at
        ``theta``).
    step : float, optional
        The integration step [s], which sets the joint friction's bristles (`_drives`;
        needed only with dry friction).

    Returns
    -------
    ArmSystem
        The assembled system and its handles.
    """
    p = params
    th1, th2 = float(theta[0]), float(theta[1])
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    rigid_nodes: list[int] = []

    def rigid_node(pos, angle) -> int:
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[pos[0], pos[1], angle]))
        rigid_nodes.append(node)
        return node

    def body_on(node, mass, inertia) -> None:
        if mass > 0.0 or inertia > 0.0:
            mbs.AddObject(ObjectRigidBody2D(nodeNumber=node, mass=mass, inertia=inertia))

    def clamp(marker0, node1, relative_angle=0.0) -> None:
        """Fix node ``node1`` to ``marker0`` in position and in-plane rotation, keeping
        the relative angle ``relative_angle`` that node 1 has in the reference layout."""
        frame = exu.HT(rotation=_rot3(-relative_angle), translation=[0.0, 0.0, 0.0])
        marker1 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=node1, localHT=frame))
        mbs.AddObject(ObjectJointGeneric(markerNumbers=[marker0, marker1], constrainedAxes=_CLAMP))

    e1 = np.array([np.cos(th1), np.sin(th1)])
    e2 = np.array([np.cos(th1 + th2), np.sin(th1 + th2)])
    tip1 = p.L1 * e1
    tip2 = tip1 + p.L2 * e2
    n_el1, n_el2 = mesh.elements_per_link

    # Hub 1 turning on the base.
    hub1 = rigid_node([0.0, 0.0], th1)
    m_hub1 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=hub1))
    m_ground_rigid = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=[0, 0, 0]))
    if lock_joints:
        clamp(m_ground_rigid, hub1, th1)
    else:
        m_ground = mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[0, 0, 0]))
        mbs.AddObject(ObjectJointRevolute2D(
            markerNumbers=[m_ground, mbs.AddMarker(MarkerNodePosition(nodeNumber=hub1))]))

    def template(rho, EI, d):
        return beam_template(mesh, rho=rho, EI=EI, damping=d)

    # Link 1 (+ stator at its tip).
    if mesh.element == "ancf":
        gen1 = exudyn.beams.GenerateBeamElementsAlongLine(
            mbs, [0, 0, 0], [*tip1, 0], n_el1, template(p.rho1, p.EI1, p.bending_damping1))
        nodes1 = gen1["nodes"]
        clamp(m_hub1, nodes1[0])
    else:  # the beam's rigid nodes are the hub's: hub 1 shares link 1's root node
        gen1 = exudyn.beams.GenerateBeamElementsAlongLine(
            mbs, [0, 0, 0], [*tip1, 0], n_el1, template(p.rho1, p.EI1, p.bending_damping1),
            nodeNumberStart=hub1)
        nodes1 = gen1["nodes"]
        rigid_nodes.extend(n for n in nodes1 if n != hub1)
    body_on(hub1, p.mh1, p.Jh1)
    m_tip1 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes1[-1]))
    if p.stator_inertia > 0.0:
        stator = rigid_node(tip1, th1)
        body_on(stator, p.stator_mass, p.stator_inertia)
        clamp(m_tip1, stator)
        stator_mass_on_hub2 = 0.0
    else:  # a point mass at the joint moves with hub 2's centre: lump it there
        stator, stator_mass_on_hub2 = None, p.stator_mass

    # Hub 2 on joint 2 at the link-1 tip.
    hub2 = rigid_node(tip1, th1 + th2)
    m_hub2 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=hub2))
    if lock_joints:
        clamp(m_tip1, hub2, th2)
    else:
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[
            mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes1[-1])),
            mbs.AddMarker(MarkerNodePosition(nodeNumber=hub2))]))
    body_on(hub2, p.mh2 + stator_mass_on_hub2, p.Jh2)

    # Link 2 and payload.
    if mesh.element == "ancf":
        gen2 = exudyn.beams.GenerateBeamElementsAlongLine(
            mbs, [*tip1, 0], [*tip2, 0], n_el2, template(p.rho2, p.EI2, p.bending_damping2))
        nodes2 = gen2["nodes"]
        clamp(m_hub2, nodes2[0])
        payload = None
        if p.Mp > 0.0 or p.Jp > 0.0:
            payload = rigid_node(tip2, th1 + th2)
            body_on(payload, p.Mp, p.Jp)
            clamp(mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes2[-1])), payload)
    else:
        gen2 = exudyn.beams.GenerateBeamElementsAlongLine(
            mbs, [*tip1, 0], [*tip2, 0], n_el2, template(p.rho2, p.EI2, p.bending_damping2),
            nodeNumberStart=hub2)
        nodes2 = gen2["nodes"]
        rigid_nodes.extend(n for n in nodes2 if n != hub2)
        payload = nodes2[-1]
        body_on(payload, p.Mp, p.Jp)

    # Torques: τ1 on hub 1; τ2 on hub 2 and its reaction on the link-1 tip (stator side).
    load_markers = (m_hub1, m_hub2, m_tip1)
    loads = tuple(mbs.AddLoad(LoadTorqueVector(markerNumber=m, loadVector=[0, 0, 0]))
                  for m in load_markers)
    tip_node = payload if payload is not None else nodes2[-1]
    tip_load = mbs.AddLoad(LoadForceVector(
        markerNumber=mbs.AddMarker(MarkerNodePosition(nodeNumber=tip_node)), loadVector=[0, 0, 0]))
    joints = add_joints(mbs, p, hub1=hub1, hub2=hub2, stator=stator, hub1_load=loads[0],
                        hub2_loads=(loads[1], loads[2]), references=(th1, th1 + th2),
                        step=step)
    mbs.Assemble()

    links = (LinkNodes(list(nodes1), np.linspace(0.0, p.L1, n_el1 + 1)),
             LinkNodes(list(nodes2), np.linspace(0.0, p.L2, n_el2 + 1)))
    for link in links:
        link.coords = np.array([mbs.systemData.GetNodeLTGODE2(n) for n in link.nodes])
    return ArmSystem(SC, mbs, mesh.element, links, hub1, hub2, stator, payload, loads,
                     load_markers, tip_load, rigid_nodes, joints)


def simulation_settings(*, step: float, spectral_radius: float = 0.9,
                        newton_tolerance: float = 1e-6) -> exu.SimulationSettings:
    """Generalised-α settings measured on this model (docs, *The truth plant*).

    Newton tolerances 1e-6 (the default absolute 1e-10 is below ANCF round-off), sparse
    linear solver reusing its analysed pattern, no solution file, no console output,
    fixed step ``step``, halved on Newton failure down to step/1000 (ten halvings;
    Exudyn's default 1e-8 s makes a hopeless step take seconds to be declared failed).

    Parameters
    ----------
    step : float
        The integration step [s].
    spectral_radius : float
        Generalised-α's spectral radius at infinity, in [0, 1] (default 0.9: a little
        numerical damping of the mesh's highest modes).
    newton_tolerance : float
        Relative and absolute Newton tolerance (default 1e-6).

    Returns
    -------
    exudyn.SimulationSettings
    """
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.endTime = step
    ti.numberOfSteps = 1
    ti.startTime = 0.0
    ti.verboseMode = 0
    ti.automaticStepSize = False
    ti.minimumStepSize = step * 1e-3
    ti.newton.absoluteTolerance = newton_tolerance
    ti.newton.relativeTolerance = newton_tolerance
    ti.generalizedAlpha.spectralRadius = spectral_radius
    ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    ss.linearSolver.reuseAnalyzedPattern = True  # the sparsity never changes: identical results
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = 1e30
    ss.show.computationTime = False
    ss.show.statistics = False
    return ss
