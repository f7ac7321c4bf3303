"""The arm's joints beyond ideal ones in the Exudyn model: friction with stiction, drives
(gear compliance with backlash, reflected rotor inertia) and the inputs they change —
the same joint model as the reduced plant's (`reduced_model.joints.kernels`, whose docstring
states it; docs/theory/joints.rst).

Friction is Exudyn's ``CoordinateSpringDamperExt`` with the bristle model
(``frictionProportionalZone = 0``, Exudyn's recommendation for its implicit solver):
stuck, a stiff spring-damper about the last sticking position holds the joint; it slips
when that holding torque exceeds the breakaway level, and sticks again when the velocity
reverses (a post-Newton switch, the step repeated).  The viscous part is the connector's
linear damping.  The bristle is resolved by the integration step h: on the inertia J it
holds its natural frequency is 1/h and its damping ratio `BRISTLE_DAMPING_RATIO`
(stiffness J/h², damping 2ζJ/h).

A spring-damper behind an inertia always overshoots a force step (the inertia must
decelerate again), by 4.8 % at ζ = 2 (13.5 % at ζ = 1), and the switch compares the
bristle's whole force, spring and damper, with the breakaway level: left to find a torque
step through its own transient, a stuck joint would break loose below breakaway.  So the
exact hold (`_hold`) treats a stuck bristle at a load jump as the constraint it stands
for: the step restarts with the accelerations of the arm with that joint held and the
bristle's sticking position moved so that it carries the new holding torque from the
step's start (`Joints.sticks` tells the hold where the bristles are); a joint whose new
holding torque exceeds breakaway is left to slip.  A constant torque then holds up to
breakaway itself.  What still loads the bristle smoothly (the arm's motion), and the
switch from slip to stick, it follows through its own dynamics: ζ = 2 keeps that overshoot
small while its fast pole, −(2 + √3)/h, stays within what the step resolves.  Its
deflection under such loads, of order τs h²/J, vanishes as the step is refined: the
bristle tends to the reduced plant's exact stick (docs/theory/joints.rst).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from exudyn.itemInterface import (CoordinateSpringDamperExt, LoadCoordinate,
                                  MarkerNodeCoordinate, NodeGenericData, NodeGenericODE2,
                                  NodePointGround, ObjectGenericODE2)

from ._bodies import rigid_body

__all__ = ["BRISTLE_DAMPING_RATIO", "Joints", "add_joints"]

#: Damping ratio of a friction bristle (module docstring).
BRISTLE_DAMPING_RATIO = 2.0


@dataclass
class Joints:
    """What the joints add to an assembled arm.

    Attributes
    ----------
    inputs : list
        Per motor torque (τ1 … τN), the loads it sets: (load, parameter, value per N m).
    rotors : list
        Per joint, its rotor node (None: no drive).
    friction : list
        Per bristle connector, (data node, (node, coordinate) of its base and of its
        moving side, joint number from 1, the connector).
    stators : tuple
        Per joint, the node whose rotation is its base (None for joint 1, on the ground).
    ground : int or None
        The ground node (joint 1's base, if needed).
    """

    inputs: list = field(default_factory=list)
    rotors: list = field(default_factory=list)
    friction: list = field(default_factory=list)
    stators: tuple = ()
    ground: int | None = None

    def motor_reader(self, mbs):
        """A function ``read(u, v, truth, m)`` writing the motor angles and rates into the
        truth vector's last 2N entries (``m``: where the rates start), from the ODE2
        displacements ``u`` and rates ``v`` of the assembled ``mbs`` (module docstring:
        a rotor's angle is absolute; joint i > 1's motor angle is relative to its
        stator)."""
        sd = mbs.systemData
        ref = lambda node, k: mbs.GetNodeParameter(node, "referenceCoordinates")[k]  # noqa
        N = len(self.rotors)
        rotors = [None if r is None else (sd.GetNodeLTGODE2(r)[0], ref(r, 0))
                  for r in self.rotors]
        stators = [(sd.GetNodeLTGODE2(s)[2], ref(s, 2)) if i > 0 and r is not None else None
                   for i, (r, s) in enumerate(zip(self.rotors, self.stators))]

        def read(u, v, truth, m):
            for i, rotor in enumerate(rotors):
                if rotor is None:
                    truth[-2 * N + i], truth[-N + i] = truth[i], truth[m + i]
                    continue
                angle, rate = rotor[1] + u[rotor[0]], v[rotor[0]]
                stator = stators[i]
                if stator is not None:  # relative to the stator
                    angle -= stator[1] + u[stator[0]]
                    rate -= v[stator[0]]
                truth[-2 * N + i], truth[-N + i] = angle, rate
        return read

    def sticks(self, mbs) -> list[tuple]:
        """The friction bristles of the assembled ``mbs`` as `ExactHold` keeps them stuck
        across a load jump: (base, moving, mode, position, stiffness, damping, level)."""
        sd = mbs.systemData
        rows = []
        for node, base, moving, _, connector in self.friction:
            index = [-1 if side[0] == self.ground else sd.GetNodeLTGODE2(side[0])[side[1]]
                     for side in (base, moving)]
            get = lambda name: mbs.GetObjectParameter(connector, name)  # noqa: E731
            rows.append((*index, *sd.GetNodeLTGData(node)[:2], get("stickingStiffness"),
                         get("stickingDamping"),
                         get("dynamicFrictionForce") + get("staticFrictionOffsetForce")))
        return rows

    def initial_data(self, mbs, u, v) -> np.ndarray:
        """The data coordinates at the ODE2 displacements ``u`` and rates ``v``: every
        bristle stuck where it stands if its joint is at rest (else slipping its way), no
        gear in its backlash's contact."""
        sd = mbs.systemData
        data = np.zeros(sd.DataSize())
        for node, base, moving, *_ in self.friction:
            def value(x, side):
                return 0.0 if side[0] == self.ground else x[sd.GetNodeLTGODE2(side[0])[side[1]]]
            rel, rate = value(u, moving) - value(u, base), value(v, moving) - value(v, base)
            k = sd.GetNodeLTGData(node)
            data[k[0]] = 0.0 if rate == 0.0 else math.copysign(1.0, rate)
            data[k[1]] = rel
        return data


def _rotary_inertia(params, i: int, moving: bool) -> float:
    """The rotary inertia of link ``i`` (from 0) at joint i's rotation coordinate
    (``moving``: the hub of a flexible link) or at joint i+1's (the stator at its tip);
    a rigid link turns as one body about its root."""
    link = params.links[i]
    if link.rigid:
        mass, centre, inertia = rigid_body(params, i)
        return inertia + mass * centre**2
    return link.hub_inertia if moving else link.stator_inertia


def _local_inertia(params, i: int) -> float:
    """The inertia a friction bristle of joint ``i`` (from 1) holds at its own (high)
    frequency: the rotor, or the hub; for joint i > 1 in series with the stator it turns
    against."""
    joint = params.joints[i - 1]
    moving = joint.rotor_inertia if joint.has_drive else _rotary_inertia(params, i - 1, True)
    if i == 1:
        return moving
    stator = _rotary_inertia(params, i - 2, False)
    return moving * stator / (moving + stator)


def add_joints(mbs, params, *, hubs, stators, hub_loads, reactions, references,
               step: float | None) -> Joints:
    """Add ``params``' joint friction and drives to the arm in ``mbs`` (before it is
    assembled).  Per joint: ``hubs`` its moving rotation's node, ``stators`` its base's
    (None for joint 1), ``hub_loads`` the ideal joint's torque load on the hub,
    ``reactions`` its reaction's on the previous link's tip (None for joint 1),
    ``references`` the hub's reference angle; ``step`` the integration step that
    resolves the friction bristles (needed only where a joint has dry friction)."""
    joints = Joints(stators=tuple(stators))

    def coordinate(node, index):
        return mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=index))

    def base(i):
        if i > 1:
            return (stators[i - 1], 2)
        if joints.ground is None:
            joints.ground = mbs.AddNode(NodePointGround())
        return (joints.ground, 0)

    for i, hub in enumerate(hubs, start=1):
        moving = (hub, 2)
        joint, stator, reaction = params.joints[i - 1], stators[i - 1], reactions[i - 1]
        reacting = [] if reaction is None else [(reaction, "loadVector", (0.0, 0.0, -1.0))]
        rotor = None
        if joint.has_drive:
            B = joint.rotor_inertia
            rotor = mbs.AddNode(NodeGenericODE2(referenceCoordinates=[references[i - 1]],
                                                initialCoordinates=[0.0],
                                                initialCoordinates_t=[0.0],
                                                numberOfODE2Coordinates=1))
            if i == 1:
                mbs.AddObject(ObjectGenericODE2(nodeNumbers=[rotor], massMatrix=[[B]]))
            else:  # ½ B (φ̇ − α̇_s)² on [φ, x_s, y_s, α_s]
                g = np.array([1.0, 0.0, 0.0, -1.0])
                mbs.AddObject(ObjectGenericODE2(nodeNumbers=[rotor, stator],
                                                massMatrix=B * np.outer(g, g)))
            load = mbs.AddLoad(LoadCoordinate(markerNumber=coordinate(rotor, 0), load=0.0))
            joints.inputs.append([(load, "load", 1.0), *reacting])
            k, d, b = joint.gear_stiffness, joint.gear_damping, joint.backlash
            gear = dict(stiffness=k, damping=d) if b == 0 else dict(
                useLimitStops=True, limitStopsLower=-b / 2, limitStopsUpper=b / 2,
                limitStopsStiffness=k, limitStopsDamping=d,
                nodeNumber=mbs.AddNode(NodeGenericData(numberOfDataCoordinates=3,
                                                       initialCoordinates=[0.0] * 3)))
            mbs.AddObject(CoordinateSpringDamperExt(
                markerNumbers=[coordinate(rotor, 0), coordinate(*moving)], **gear))
            moving = (rotor, 0)
        else:
            joints.inputs.append([(hub_loads[i - 1], "loadVector", (0.0, 0.0, 1.0)), *reacting])
        joints.rotors.append(rotor)
        _add_friction(mbs, params, i, base(i) if _has_friction(params, i) else None, moving,
                      coordinate, joints, step)
    return joints


def _has_friction(params, i: int) -> bool:
    joint = params.joints[i - 1]
    return joint.static_friction > 0 or joint.viscous > 0


def _add_friction(mbs, params, i, base, moving, coordinate, joints, step) -> None:
    """Joint ``i``'s friction between the coordinates ``base`` and ``moving`` (module
    docstring); nothing where it has none (``base`` None)."""
    if base is None:
        return
    joint = params.joints[i - 1]
    static, coulomb, viscous = joint.static_friction, joint.coulomb, joint.viscous
    options = dict(damping=viscous)
    if static > 0:
        if step is None:
            raise ValueError("dry joint friction needs the integration step its bristle is "
                             "resolved by")
        inertia = _local_inertia(params, i)
        data = mbs.AddNode(NodeGenericData(numberOfDataCoordinates=3,
                                           initialCoordinates=[0.0] * 3))
        options.update(
            nodeNumber=data, dynamicFrictionForce=coulomb,
            staticFrictionOffsetForce=static - coulomb,
            exponentialDecayStatic=joint.stribeck_velocity or 1.0,
            stickingStiffness=inertia / step**2,
            stickingDamping=2.0 * BRISTLE_DAMPING_RATIO * inertia / step,
            frictionProportionalZone=0.0)
    connector = mbs.AddObject(CoordinateSpringDamperExt(
        markerNumbers=[coordinate(*base), coordinate(*moving)], **options))
    if static > 0:
        joints.friction.append((data, base, moving, i, connector))
