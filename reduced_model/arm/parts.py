"""The parts of an arm description — `Link`, `Joint`, `Payload` — made from the field
declarations of `reduced_model.arm.fields`, so that each field is declared once; flat keys
(``EI1``: a field's key stem and its link or joint number from 1) and the error of one bad
field.  ``stator_mass`` and ``stator_inertia`` without a number are link 1's on a two-link
arm (the motor-2 stator)."""
from __future__ import annotations

import dataclasses
import difflib

from .fields import JOINT_FIELDS, LINK_FIELDS, PAYLOAD_FIELDS, Field

__all__ = ["FieldError", "Link", "Joint", "Payload", "flat_key_field", "field_key",
           "suggestion"]


class FieldError(ValueError):
    """A bad value of one field of an arm; ``field`` names it (a flat key such as ``EI1``,
    or ``links``, ``gravity``), ``reason`` says what is wrong (configuration loaders
    prefix the field with its full path).

    Parameters
    ----------
    owner : str
        The object the field belongs to (``"ArmParameters"``), the message's prefix.
    field : str
        The field's name (``"EI1"``).
    reason : str
        What is wrong with its value (``"must be > 0, got -1.0"``).

    Examples
    --------
    >>> from reduced_model import ArmParameters, FieldError
    >>> try:
    ...     ArmParameters(EI1=-1.0)
    ... except FieldError as exc:
    ...     print(exc.field, "—", exc)
    EI1 — ArmParameters.EI1 must be >= 0, got -1.0
    """

    def __init__(self, owner: str, field: str, reason: str) -> None:
        self.field, self.reason = field, reason
        super().__init__(f"{owner}.{field} {reason}")


def _part(name: str, declared: tuple[Field, ...], doc: str, defaults: dict):
    """A frozen dataclass with one float field per declaration (``modes`` an int)."""
    def post_init(self):
        for f in declared:
            value = getattr(self, f.name)
            reason = f.check(value)
            if reason:
                raise FieldError(name, f.name, reason)
            object.__setattr__(self, f.name, int(value) if f.integer else float(value))

    lines = [doc, "", "Parameters", "----------"]
    for f in declared:
        lines += [f"{f.name} : {'int' if f.integer else 'float'}",
                  f"    {f.meaning[0].upper()}{f.meaning[1:]}" + (f" [{f.unit}]" if f.unit else "")
                  + (f"; typically {f.typical}" if f.typical else "") + "."]
    cls = dataclasses.make_dataclass(
        name, [(f.name, int if f.integer else float,
                dataclasses.field(default=defaults.get(f.name, 0))) for f in declared],
        frozen=True, namespace={"__post_init__": post_init, "__doc__": "\n".join(lines)})
    cls.__module__ = __name__
    return cls


Link = _part("Link", LINK_FIELDS, "One link of the arm: a uniform Euler–Bernoulli beam "
             "clamped to the hub at its root (``modes`` > 0), or a rigid body (``modes`` = 0).",
             {"modes": 2})
Joint = _part("Joint", JOINT_FIELDS, "The joint at a link's root, beyond the ideal revolute "
              "joint: friction with stiction, a drive (gear compliance, backlash, reflected "
              "rotor inertia) and the current loop's lag; all 0 is the paper's ideal joint "
              "(docs/theory/joints.rst).", {})
Payload = _part("Payload", PAYLOAD_FIELDS, "The payload, rigidly at the last link's tip.", {})
Joint.static_friction = property(
    lambda self: max(self.breakaway, self.coulomb),
    doc="The breakaway torque [N m]: the static level, at least the Coulomb level (0: no "
        "dry friction).")
Joint.has_drive = property(lambda self: self.gear_stiffness > 0,
                           doc="Whether the joint has a drive (gear compliance and rotor).")
Link.rigid = property(lambda self: self.modes == 0, doc="Whether the link is rigid.")
Link.mass = property(lambda self: self.mass_per_length * self.length, doc="Its mass [kg].")
Link.root_inertia = property(lambda self: self.mass_per_length * self.length**3 / 3.0,
                             doc="Its inertia about its root, ρL³/3 [kg m²] (the paper's "
                                 "J0i; Table 1 rounds 0.041667 to 0.0415).")

_LINK = {f.key: f for f in LINK_FIELDS}
_JOINT = {f.key: f for f in JOINT_FIELDS}
_PAYLOAD = {f.key: f for f in PAYLOAD_FIELDS}
#: Two-link names without a number: the motor-2 stator is link 1's.
_TWO_LINK_ALIASES = {"stator_mass": "stator_mass1", "stator_inertia": "stator_inertia1"}


def flat_key_field(key: str, n_links: int) -> tuple[str, int | None, Field] | None:
    """(``"link"``/``"joint"``/``"payload"``, index from 0 or None, `Field`) of the flat
    key ``key`` on an arm of ``n_links`` links; None where it names no field (``gravity``
    is not a field: it is a 2-vector)."""
    if n_links == 2:
        key = _TWO_LINK_ALIASES.get(key, key)
    if key in _PAYLOAD:
        return "payload", None, _PAYLOAD[key]
    stem, number = key[:-1], key[-1:]
    if not number.isdigit() or not 1 <= int(number) <= n_links:
        return None
    for owner, table in (("link", _LINK), ("joint", _JOINT)):
        if stem in table:
            return owner, int(number) - 1, table[stem]
    return None


def field_key(name: str) -> str:
    """The flat key stem of a field named ``name``."""
    for f in (*LINK_FIELDS, *JOINT_FIELDS, *PAYLOAD_FIELDS):
        if f.name == name:
            return f.key
    return name


def suggestion(key: str, allowed) -> str:
    """`` (did you mean X?)`` for the closest of ``allowed`` to ``key``, else ""."""
    close = difflib.get_close_matches(key, list(allowed), n=1)
    return f" (did you mean {close[0]}?)" if close else ""
