"""The arm's joints beyond ideal ones in the Exudyn model: friction with stiction, drives
(gear compliance with backlash, reflected rotor inertia) and the inputs they change —
the same joint model as the reduced plant's (`reduced_model._joints`, whose docstring
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

__all__ = ["BRISTLE_DAMPING_RATIO", "Joints", "add_joints"]

#: Damping ratio of a friction bristle (module docstring).
BRISTLE_DAMPING_RATIO = 2.0


@dataclass
class Joints:
    """What the joints add to an assembled arm.

    Attributes
    ----------
    inputs : list
        Per motor torque (τ1, τ2), the loads it sets: (load, parameter, value per N m).
    rotors : list
        Per joint, its rotor node (None: no drive).
    friction : list
        Per bristle connector, (data node, (node, coordinate) of its base and of its
        moving side, joint 1 or 2, the connector).
    stator, ground : int or None
        The stator's node (joint 2's base), the ground node (joint 1's, if needed).
    """

    inputs: list = field(default_factory=list)
    rotors: list = field(default_factory=lambda: [None, None])
    friction: list = field(default_factory=list)
    stator: int | None = None
    ground: int | None = None

    def motor_reader(self, mbs):
        """A function ``read(u, v, truth, m)`` writing the motor angles and rates into the
        truth vector's last four entries (``m``: where the rates start), from the ODE2
        displacements ``u`` and rates ``v`` of the assembled ``mbs`` (module docstring:
        a rotor's angle is absolute; joint 2's motor angle is relative to the stator)."""
        sd = mbs.systemData
        ref = lambda node, k: mbs.GetNodeParameter(node, "referenceCoordinates")[k]  # noqa
        rotors = [None if r is None else (sd.GetNodeLTGODE2(r)[0], ref(r, 0))
                  for r in self.rotors]
        stator = ((sd.GetNodeLTGODE2(self.stator)[2], ref(self.stator, 2))
                  if self.rotors[1] is not None else None)

        def read(u, v, truth, m):
            for i, rotor in enumerate(rotors):
                if rotor is None:
                    truth[-4 + i], truth[-2 + i] = truth[i], truth[m + i]
                    continue
                angle, rate = rotor[1] + u[rotor[0]], v[rotor[0]]
                if i == 1:  # relative to the stator
                    angle -= stator[1] + u[stator[0]]
                    rate -= v[stator[0]]
                truth[-4 + i], truth[-2 + i] = angle, rate
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


def _local_inertia(params, i: int) -> float:
    """The inertia a friction bristle of joint ``i`` holds at its own (high) frequency:
    the rotor, or the hub; for joint 2 in series with the stator it turns against."""
    moving = params.rotor_inertia2 if params.has_drive(i) and i == 2 else (
        params.rotor_inertia1 if params.has_drive(i) else (params.Jh1 if i == 1 else params.Jh2))
    if i == 1:
        return moving
    return moving * params.stator_inertia / (moving + params.stator_inertia)


def add_joints(mbs, params, *, hub1: int, hub2: int, stator: int | None, hub1_load: int,
               hub2_loads: tuple[int, int], references: tuple[float, float],
               step: float | None) -> Joints:
    """Add ``params``' joint friction and drives to the arm in ``mbs`` (before it is
    assembled).  ``hub1_load``, ``hub2_loads`` are the ideal joints' torque loads (hub 1;
    hub 2 and its reaction on the link-1 tip), ``references`` the hubs' reference angles,
    ``step`` the integration step that resolves the friction bristles (needed only where
    a joint has dry friction)."""
    joints = Joints(stator=stator)

    def coordinate(node, index):
        return mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=index))

    def base(i):
        if i == 2:
            return (stator, 2)
        if joints.ground is None:
            joints.ground = mbs.AddNode(NodePointGround())
        return (joints.ground, 0)

    for i, hub in ((1, hub1), (2, hub2)):
        moving = (hub, 2)
        if params.has_drive(i):
            B = getattr(params, f"rotor_inertia{i}")
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
            joints.rotors[i - 1] = rotor
            load = mbs.AddLoad(LoadCoordinate(markerNumber=coordinate(rotor, 0), load=0.0))
            joints.inputs.append([(load, "load", 1.0)] if i == 1 else
                                 [(load, "load", 1.0), (hub2_loads[1], "loadVector",
                                                        (0.0, 0.0, -1.0))])
            k, d, b = (getattr(params, f"{name}{i}") for name in
                       ("gear_stiffness", "gear_damping", "backlash"))
            gear = dict(stiffness=k, damping=d) if b == 0 else dict(
                useLimitStops=True, limitStopsLower=-b / 2, limitStopsUpper=b / 2,
                limitStopsStiffness=k, limitStopsDamping=d,
                nodeNumber=mbs.AddNode(NodeGenericData(numberOfDataCoordinates=3,
                                                       initialCoordinates=[0.0] * 3)))
            mbs.AddObject(CoordinateSpringDamperExt(
                markerNumbers=[coordinate(rotor, 0), coordinate(*moving)], **gear))
            moving = (rotor, 0)
        else:
            joints.inputs.append([(hub1_load, "loadVector", (0.0, 0.0, 1.0))] if i == 1 else
                                 [(hub2_loads[0], "loadVector", (0.0, 0.0, 1.0)),
                                  (hub2_loads[1], "loadVector", (0.0, 0.0, -1.0))])
        _add_friction(mbs, params, i, base(i) if _has_friction(params, i) else None, moving,
                      coordinate, joints, step)
    return joints


def _has_friction(params, i: int) -> bool:
    return params.static_friction(i) > 0 or getattr(params, f"viscous{i}") > 0


def _add_friction(mbs, params, i, base, moving, coordinate, joints, step) -> None:
    """Joint ``i``'s friction between the coordinates ``base`` and ``moving`` (module
    docstring); nothing where it has none (``base`` None)."""
    if base is None:
        return
    static, coulomb = params.static_friction(i), getattr(params, f"coulomb{i}")
    viscous = getattr(params, f"viscous{i}")
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
            exponentialDecayStatic=getattr(params, f"stribeck_velocity{i}") or 1.0,
            stickingStiffness=inertia / step**2,
            stickingDamping=2.0 * BRISTLE_DAMPING_RATIO * inertia / step,
            frictionProportionalZone=0.0)
    connector = mbs.AddObject(CoordinateSpringDamperExt(
        markerNumbers=[coordinate(*base), coordinate(*moving)], **options))
    if static > 0:
        joints.friction.append((data, base, moving, i, connector))
