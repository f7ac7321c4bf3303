"""Build a planar serial arm of 1–4 links as an Exudyn flexible multibody system from
`ArmParameters`.

Link by link from the base out: joint i's revolute joint (to the ground, or at link
i−1's tip), then link i — a flexible link is a hub (a rigid body at its root, torque τi)
with the beam clamped to it (ANCF) or sharing its first node (geometrically exact), the
optional stator of motor i+1 rigidly at its tip; a rigid link is one rigid body carrying
its hub, its distributed mass and what sits rigidly at its tip (`_bodies`).  The reaction
−τ(i+1) of motor i+1 acts on link i's tip (the stator side); the payload sits at the last
tip, with a force input there.  The joints' friction and drives follow (`_drives`), then,
in gravity, a mass-proportional load on every beam element and rigid body.

The creation order of a two-flexible-link arm is the one the paper's arm has always been
built in: Exudyn numbers nodes, objects and markers in that order, and the numbering sets
the order in which its sums are formed, so the paper's arm computes the same numbers to
the last bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import exudyn as exu
import numpy as np
from exudyn.itemInterface import (LoadForceVector, LoadMassProportional, LoadTorqueVector,
                                  MarkerBodyMass, ObjectGround)

from reduced_model import ArmParameters

from ._bodies import ArmBuilder, LinkNodes, RigidLink, beam_template
from ._drives import Joints, add_joints
from ._mesh import Mesh

__all__ = ["ArmSystem", "LinkNodes", "RigidLink", "build_arm", "beam_template",
           "simulation_settings"]

@dataclass
class ArmSystem:
    """An assembled Exudyn system of the arm and the handles the plant needs
    (`build_arm` makes it).

    Parameters
    ----------
    SC, mbs : exudyn SystemContainer and MainSystem
        The system, assembled.
    element : str
        The beam element of the flexible links ("ancf" or "geometrically_exact").
    links : tuple of LinkNodes or RigidLink
        Each link: a flexible link's nodes, root to tip, with their arc length; a rigid
        link's body.
    hubs : tuple of int
        Per joint, the node whose rotation is the joint's moving side (a flexible link's
        hub, a rigid link's body node).
    stators : tuple of int or None
        Per joint, the node at the previous link's tip whose rotation is its base (None
        for joint 1 and where there is no rotary body there).
    payload : int or None
        The rigid body at the last flexible link's tip (the last beam node for GE
        beams; None on a rigid last link, which carries it).
    loads : tuple of int
        The torque loads: τi on each hub, then −τ(i+1) on each link i's tip.
    tip_load : int
        The force on the payload (the last tip), base frame.
    joints : Joints
        Friction, drives, and the loads each motor torque sets.
    """

    SC: exu.SystemContainer
    mbs: exu.MainSystem
    element: str
    links: tuple
    hubs: tuple[int, ...]
    stators: tuple
    payload: int | None
    loads: tuple[int, ...]
    tip_load: int
    joints: Joints

    @property
    def rigid_links(self) -> tuple[RigidLink, ...]:
        """The rigid links' bodies."""
        return tuple(link for link in self.links if isinstance(link, RigidLink))

    @property
    def beam_nodes(self) -> list[int]:
        """Every beam node of the flexible links, root to tip, link after link."""
        return [n for link in self.links if isinstance(link, LinkNodes) for n in link.nodes]


def build_arm(params: ArmParameters, mesh: Mesh = Mesh(), *, theta=None,
              lock_joints: bool = False, step: float | None = None) -> ArmSystem:
    """Create and assemble the arm with its links laid out straight at joint angles
    ``theta``.

    Parameters
    ----------
    params : ArmParameters
        The arm.
    mesh : Mesh
        The beam element and the elements of each flexible link (default ANCF, 4).
    theta : sequence of float, optional
        Joint angles [rad] of the straight reference configuration, one per joint
        (default 0).
    lock_joints : bool
        Replace the revolute joints by clamps (for locked-joint modal analysis at
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
    N = p.n_links
    theta = np.zeros(N) if theta is None else np.asarray(theta, dtype=float)
    if theta.shape != (N,):
        raise ValueError(f"theta must be {N} joint angles, got shape {theta.shape}")
    counts = mesh.counts(p)
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    arm = ArmBuilder(mbs, p, mesh, ground=ground, lock_joints=lock_joints)
    angle, root = 0.0, np.zeros(2)
    for i in range(N):
        angle = angle + float(theta[i])
        if p.links[i].rigid:
            arm.rigid_link(i, root, angle, float(theta[i]))
        else:
            arm.flexible_link(i, root, angle, float(theta[i]), counts[i])
        root = arm.tip_position

    mbs_load = mbs.AddLoad
    loads = tuple(mbs_load(LoadTorqueVector(markerNumber=m, loadVector=[0, 0, 0]))
                  for m in (*arm.hub_markers, *arm.tip_markers))
    tip_load = mbs_load(LoadForceVector(markerNumber=arm.tip_position_marker(),
                                        loadVector=[0, 0, 0]))
    hub_loads = loads[:N]
    reactions = (None, *loads[N:])
    joints = add_joints(mbs, p, hubs=arm.hubs, stators=arm.stators, hub_loads=hub_loads,
                        reactions=reactions, references=arm.hub_angles, step=step)
    if any(p.gravity):  # on every mass: ρ g on the beams, m g on the rigid bodies
        g = [p.gravity[0], p.gravity[1], 0.0]
        for body in arm.massive:
            mbs_load(LoadMassProportional(
                markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=body)), loadVector=g))
    mbs.Assemble()

    for link in arm.links:
        if isinstance(link, LinkNodes):
            link.coords = np.array([mbs.systemData.GetNodeLTGODE2(n) for n in link.nodes])
    return ArmSystem(SC, mbs, mesh.element, tuple(arm.links), tuple(arm.hubs),
                     tuple(arm.stators), arm.payload, loads, tip_load, joints)


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
