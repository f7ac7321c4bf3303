"""What a fit of the joints' friction and drive parameters needs: a start and bounds
that keep every point the fit may try an arm (``flexarm calibrate --fit
true_params.coulomb1,…``; the fields are `ArmParameters`' joint fields).

Every joint field is 0 by default (the paper's ideal joints), and the fit measures a
parameter relative to its start: a field that is 0 in the scenario, fitted with no start
and no finite bounds, is refused with its typical range (docs/theory/joints.rst's table)
and an example.  Some fields are tied to others (`ArmParameters._check_joint`):

* a drive's ``gear_stiffness`` and ``rotor_inertia`` are both > 0 or both 0 (0 is a rigid
  joint, another model): fitted, both stay > 0 — the joint must have a drive, and their
  lower bounds must be > 0 (no default: it is a property of the gear);
  ``gear_damping`` and ``backlash`` need a drive;
* ``breakaway`` is 0 (the Coulomb level) or at least ``coulomb``: fitted with ``coulomb``
  fixed, its lower bound defaults to the Coulomb level; ``coulomb`` fitted with a
  breakaway fixed above 0 has that breakaway as its default upper bound; both fitted,
  their bounds must not overlap;
* a breakaway above the Coulomb level needs a ``stribeck_velocity`` > 0 (fitted: its
  lower bound > 0).

Anything else the scenario refuses at the start values is refused here too, naming
``calibrate.start`` (a trial point outside the arms would be read as a failed
simulation, not a slope).
"""
from __future__ import annotations

import math

from reduced_model import ArmParameters
from reduced_model.arm import JOINT_FIELDS, MAX_LINKS

from ...run.config import ConfigError, check

__all__ = ["joint_bounds", "check_overlap", "check_start_arm", "TYPICAL"]

#: Per joint field (without its joint number): the typical range in words, an example
#: start and bounds — from the field's declaration (`reduced_model.arm.JOINT_FIELDS`).
TYPICAL = {f.name: (f.typical, f.example, f.bounds) for f in JOINT_FIELDS}
_DRIVE = ("gear_stiffness", "rotor_inertia")
_NEED_DRIVE = ("gear_damping", "backlash")


def _joint_field(field: str) -> tuple[str, int] | None:
    """("coulomb", 1) for "coulomb1"; None for a field that is not a joint's."""
    stem, joint = field[:-1], field[-1:]
    return (stem, int(joint)) if stem in TYPICAL and joint.isdigit() and \
        1 <= int(joint) <= MAX_LINKS else None


def _example(name: str, stem: str) -> str:
    text, start, (lo, hi) = TYPICAL[stem]
    return (f'typical: {text}; e.g. [calibrate] start = {{ "{name}" = {start:g} }}, '
            f'bounds = {{ "{name}" = [{lo:g}, {hi:g}] }}')


def joint_bounds(name: str, field: str, arm: ArmParameters, given: dict, fitted: dict,
                 lower: float, upper: float) -> tuple[float, float]:
    """The bounds of the fitted field ``field`` (``name`` its dotted name) of the arm
    ``arm``: ``lower``, ``upper`` as given or defaulted (module docstring), checked.

    ``given``: the fields whose bounds the user gave; ``fitted``: every fitted
    field to its start.  Raises ConfigError naming ``--fit NAME``, ``calibrate.start`` or
    ``calibrate.bounds``, with the typical values where a start or bounds are missing."""
    joint = _joint_field(field)
    if joint is None:
        return lower, upper
    stem, i = joint
    where = f"calibrate.bounds.{name}"
    value = fitted[field]
    if value == 0 and field not in given and upper == math.inf:
        raise ConfigError(f"--fit {name}", f"is 0 in the scenario (an ideal joint) and has no "
                                            f"start or bounds: the fit measures it relative "
                                            f"to its start; give both ({_example(name, stem)})")
    if stem in _DRIVE + _NEED_DRIVE:
        check(arm.joints[i - 1].has_drive or f"gear_stiffness{i}" in fitted, f"--fit {name}",
              f"joint {i} has no drive (gear_stiffness{i} = 0): set gear_stiffness{i} and "
              f"rotor_inertia{i} in the scenario (a drive is another model, not a value)")
    if stem in _DRIVE:
        check(lower > 0, where, f"the lower bound must be > 0 (0 is a rigid joint, another "
                                f"model), got {lower:g} ({_example(name, stem)})")
    other = lambda stem_: fitted.get(f"{stem_}{i}")  # noqa: E731
    coulomb, breakaway = f"coulomb{i}", f"breakaway{i}"
    if stem == "coulomb" and other("breakaway") is None and getattr(arm, breakaway) > 0:
        limit = getattr(arm, breakaway)
        upper = min(upper, limit) if field not in given else upper
        check(upper <= limit, where, f"the upper bound {upper:g} is above {breakaway} = "
                                     f"{limit:g} (fixed), which must be >= {coulomb}: "
                                     f"bound {coulomb} by it, or fit {breakaway} too")
    if stem == "breakaway" and other("coulomb") is None:
        limit = getattr(arm, coulomb)
        lower = max(lower, limit) if field not in given else lower
        check(lower >= limit, where, f"the lower bound {lower:g} is below {coulomb} = "
                                     f"{limit:g} (fixed): a breakaway is at least the "
                                     f"Coulomb level")
    if stem == "breakaway" and other("stribeck_velocity") is None:
        check(getattr(arm, f"stribeck_velocity{i}") > 0, f"--fit {name}",
              f"needs stribeck_velocity{i} > 0 (the friction falls from the breakaway to "
              f"the Coulomb level over it): set it, or fit it too")
    if stem == "stribeck_velocity":
        check(lower > 0, where, f"the lower bound must be > 0 (a breakaway above the Coulomb "
                                f"level falls over it), got {lower:g} ({_example(name, stem)})")
    return lower, upper


def check_overlap(names_bounds: dict) -> None:
    """Both ``coulomb{i}`` and ``breakaway{i}`` fitted: the Coulomb level's upper bound
    must not exceed the breakaway's lower bound (every trial point an arm).
    ``names_bounds`` maps fitted fields to (dotted name, lower, upper)."""
    for i in range(1, MAX_LINKS + 1):
        c, b = names_bounds.get(f"coulomb{i}"), names_bounds.get(f"breakaway{i}")
        if c and b:
            check(c[2] <= b[1], f"calibrate.bounds.{b[0]}",
                  f"overlaps the bounds of {c[0]} ([{c[1]:g}, {c[2]:g}] against "
                  f"[{b[1]:g}, {b[2]:g}]): a breakaway is at least the Coulomb level at every "
                  "point the fit may try; give bounds that do not overlap")


def check_start_arm(arm: ArmParameters, starts: dict) -> None:
    """The arm at the starting values must be one (ConfigError naming
    ``calibrate.start`` and the field it fails on)."""
    try:
        arm.replace(**starts)
    except ValueError as exc:
        field = getattr(exc, "field", None)
        reason = getattr(exc, "reason", str(exc))
        raise ConfigError("calibrate.start", f"the arm at the starting values is not an arm: "
                                             f"true_params.{field} {reason}") from None
