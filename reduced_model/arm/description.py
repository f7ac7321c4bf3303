"""The arm description: a planar serial arm of 1 to `MAX_LINKS` links, each rigid or
flexible, with a joint at each link's root, a payload at the last tip and gravity in the
arm's plane (De Luca and Siciliano's N-link setting; the paper's arm is two flexible
links with ideal joints in a horizontal plane) — `ArmParameters` — and its table form, one
for the named arms, a user's file and a scenario's inline ``[arm]`` table:

::

    name = "my-arm"                    # optional: how runs name it
    description = "one line"           # optional
    gravity = [0.0, -9.81]             # m/s², in the arm's plane (default: horizontal)

    [[links]]                          # from the base out, 1 to 4
    length = 0.5                       # every field of reduced_model.arm.fields.LINK_FIELDS
    mass_per_length = 1.0
    bending_stiffness = 10.0
    modes = 2                          # 0: a rigid link
    hub_inertia = 1.0

    [[joints]]                         # optional: one per link (ideal joints if absent)
    coulomb = 0.3

    [payload]
    mass = 0.1

A field has two names: structured (``arm.links[0].bending_stiffness``) and its *flat key*
(``EI1``, `reduced_model.arm.parts`), the names the two-link arm has always had and the
ones a scenario's ``true_params`` table, calibration and uncertainty use.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
from dataclasses import dataclass, fields
from importlib import resources

from .fields import JOINT_EFFECTS, JOINT_FIELDS, LINK_FIELDS, MAX_LINKS, PAYLOAD_FIELDS
from .parts import FieldError, Joint, Link, Payload, field_key, flat_key_field, suggestion

__all__ = ["ArmParameters", "ArmFileError", "arm_from_table", "arm_to_table", "ARM_KEYS"]

#: The keys of an arm table.
ARM_KEYS = ("name", "description", "gravity", "links", "joints", "payload")


#: The keys of a parameter table that describe a whole arm.
_STRUCTURE = ("links", "joints", "payload", "gravity")


@dataclass(frozen=True, init=False)
class ArmParameters:
    """A planar serial arm: links, their joints, a payload and gravity (SI units).

    ``ArmParameters()`` is the default arm (``arm = "default"``: the paper's Table 1 plus
    a motor-2 stator inertia of 0.01 kg m² and a bending damping of 2e-3 N m² s, ideal
    joints, horizontal); keyword arguments named by flat key change its fields
    (``ArmParameters(EI1=12.0)``).  An arm of your own is given by its parts, or read
    from a file (`reduced_model.arm.read_arm`).  Link i's angle θ_i is measured from the
    tangent at the previous link's tip (θ1 from the base x axis); link i's joint is at its
    root; the motor of joint i+1 has its stator at link i's tip.

    Parameters
    ----------
    links : tuple of Link
        From the base out, 1 to 4 (default: the default arm's two).
    joints : tuple of Joint
        One per link, at its root (default: ideal joints).
    payload : Payload
        At the last link's tip (default: none, unless ``links`` is not given).
    gravity : (float, float)
        Gravity (g_x, g_y) [m/s²] in the arm's plane, base frame (default (0, 0): a
        horizontal arm; a vertical arm with its base x axis horizontal has (0, −9.81)).
    **keys : float
        Fields changed by flat key (``EI1``, ``coulomb2``, ``Mp``), after the above.

    Notes
    -----
    *The stator.*  The default arm's stator inertia, 0.01 kg m² (1 % of Jh2: a ~1 kg
    housing of 0.1 m radius): the motor-2 reaction torque acts on the link-1 tip; with no
    rotary inertia there, a sampled (1 kHz) joint-2 PD with Kd2 = 4 N m s/rad diverges
    within 10 ms on *both* plants.  3e-3 kg m² is the smallest value measured to keep
    Kd2 = 4 and 6 stable on both plants; 0.01 leaves a 3× margin.  It lowers the locked
    frequencies by ≤ 0.4 % and adds a 13.7 Hz mode of the free arm.

    *The damping.*  The bending moment is EI w'' + d ẇ''.  The retardation time
    β = d / EI damps every strain of the link alike, so every mode of the arm has the
    damping ratio ζ = π f β (stiffness-proportional damping).  The default 2e-3 N m² s
    (β = 2e-4 s) is light structural damping of a metal link, not a measured value.

    *Joint physics.*  Every joint field is 0 by default: the paper's ideal joints.  Both
    plants apply them the same way (``docs/theory/joints.rst``): friction acts between
    the hub and its base (the previous link's stator) or, with a drive, between the
    rotor and the base; with a drive the motor torque turns the rotor, the compliance
    turns the hub, and the encoder reads the rotor.  Joint i > 1's friction and drive
    need a stator inertia at link i−1's tip (they act on it).
    """

    links: tuple
    joints: tuple
    payload: Payload
    gravity: tuple[float, float]

    def __init__(self, links=None, joints=None, payload=None, gravity=None, **keys) -> None:
        if links is None:
            base = _default_arm()
            links = base.links
            joints = base.joints if joints is None else joints
            payload = base.payload if payload is None else payload
            gravity = base.gravity if gravity is None else gravity
        links = tuple(links)
        joints = tuple(Joint() for _ in links) if joints is None else tuple(joints)
        set_ = object.__setattr__
        set_(self, "links", links)
        set_(self, "joints", joints)
        set_(self, "payload", Payload() if payload is None else payload)
        set_(self, "gravity", (0.0, 0.0) if gravity is None else gravity)
        self._check_structure()
        if keys:
            changed = self.replace(**keys)
            for f in fields(self):
                set_(self, f.name, getattr(changed, f.name))
            return
        for i in range(len(self.links)):
            self._check_link(i)
            self._check_joint(i)

    # --- checks -------------------------------------------------------------------------
    def _fail(self, field: str, reason: str):
        raise FieldError("ArmParameters", field, reason)

    def _check_structure(self) -> None:
        n = len(self.links)
        if not 1 <= n <= MAX_LINKS:
            self._fail("links", f"must be 1 to {MAX_LINKS} links, got {n}")
        for name, items, kind in (("links", self.links, Link), ("joints", self.joints, Joint)):
            for item in items:
                if not isinstance(item, kind):
                    self._fail(name, f"must hold {kind.__name__} objects, got {item!r}")
        if len(self.joints) != n:
            self._fail("joints", f"must be one per link ({n}), got {len(self.joints)}")
        if not isinstance(self.payload, Payload):
            self._fail("payload", f"must be a Payload, got {self.payload!r}")
        g = self.gravity
        if (not isinstance(g, (tuple, list)) or len(g) != 2
                or any(isinstance(v, bool) or not isinstance(v, (int, float))
                       or not math.isfinite(v) for v in g)):
            self._fail("gravity", f"must be two finite numbers (g_x, g_y) [m/s²] in the "
                                  f"arm's plane, got {g!r}")
        object.__setattr__(self, "gravity", (float(g[0]), float(g[1])))

    def _check_link(self, i: int) -> None:
        link, k = self.links[i], i + 1
        if link.rigid:
            for name in ("bending_stiffness", "bending_damping"):
                if getattr(link, name) != 0:
                    self._fail(f"{field_key(name)}{k}", f"must be 0 on a rigid link (modes{k} = 0): "
                                                   "it would change nothing")
        elif link.bending_stiffness <= 0:
            self._fail(f"EI{k}", f"must be > 0 on a flexible link (modes{k} = {link.modes}), "
                                 f"got {link.bending_stiffness!r}")
        if k == len(self.links):
            for name in ("stator_mass", "stator_inertia"):
                if getattr(link, name) != 0:
                    self._fail(f"{name}{k}", "must be 0 on the last link (no joint follows "
                                             "it: its tip carries the payload)")

    def _check_joint(self, i: int) -> None:
        """The joint fields of joint ``i`` (from 0) must describe a joint (FieldError
        naming one)."""
        joint, k = self.joints[i], i + 1

        def need(ok: bool, name: str, reason: str) -> None:
            if not ok:
                self._fail(f"{name}{k}", reason)
        need(joint.breakaway == 0 or joint.breakaway >= joint.coulomb, "breakaway",
             f"must be 0 (= coulomb{k}) or >= coulomb{k} = {joint.coulomb!r}, got "
             f"{joint.breakaway!r}")
        need(joint.breakaway <= joint.coulomb or joint.stribeck_velocity > 0,
             "stribeck_velocity", f"must be > 0 where breakaway{k} > coulomb{k} (the "
             "friction falls from one to the other over it)")
        need(joint.has_drive == (joint.rotor_inertia > 0), "rotor_inertia",
             f"must be > 0 where gear_stiffness{k} > 0 (a drive) and 0 where it is 0 (a "
             f"rigid joint), got {joint.rotor_inertia!r} with gear_stiffness{k} = "
             f"{joint.gear_stiffness!r}")
        for name in ("gear_damping", "backlash"):
            need(joint.has_drive or getattr(joint, name) == 0, name,
                 f"needs a drive (gear_stiffness{k} > 0)")
        acting = [n for n in (*JOINT_EFFECTS["friction"], *JOINT_EFFECTS["drive"])
                  if getattr(joint, n) > 0]
        need(i == 0 or not acting or self.links[i - 1].stator_inertia > 0,
             acting[0] if acting else "",
             f"needs a motor-{k} stator inertia at link {i}'s tip (stator_inertia{i} > 0): "
             f"joint {k}'s friction and drive act on the stator")

    # --- flat keys ----------------------------------------------------------------------
    def keys(self) -> tuple[str, ...]:
        """Every flat key of this arm (``L1`` … ``Mp``, ``Jp``, ``gravity``)."""
        out = [f"{f.key}{i + 1}" for i in range(len(self.links)) for f in LINK_FIELDS]
        out += [f"{f.key}{i + 1}" for i in range(len(self.joints)) for f in JOINT_FIELDS]
        return tuple(out) + tuple(f.key for f in PAYLOAD_FIELDS) + ("gravity",)

    def _locate(self, key: str):
        found = flat_key_field(key, len(self.links))
        if found is None:
            hint = suggestion(key, self.keys())
            raise FieldError("ArmParameters", key, f"is not a field of this {len(self.links)}"
                                                   f"-link arm{hint}")
        return found

    def get(self, key: str):
        """The value of the flat key ``key`` (``"EI1"``, ``"Mp"``, ``"gravity"``)."""
        if key == "gravity":
            return self.gravity
        owner, i, f = self._locate(key)
        part = self.payload if owner == "payload" else getattr(self, f"{owner}s")[i]
        return getattr(part, f.name)

    def __getattr__(self, name: str):
        if name.startswith("_") or "links" not in self.__dict__:
            raise AttributeError(name)
        if flat_key_field(name, len(self.links)) is None:
            raise AttributeError(f"'ArmParameters' object has no attribute {name!r}")
        return self.get(name)

    def replace(self, **keys) -> "ArmParameters":
        """A copy with fields changed by flat key (validated like the constructor)."""
        links, joints = list(self.links), list(self.joints)
        payload, gravity = self.payload, self.gravity
        changes: dict = {}
        for key, value in keys.items():
            if key == "gravity":
                gravity = value
                continue
            owner, i, f = self._locate(key)
            changes.setdefault((owner, i), {})[f.name] = value
        try:
            for (owner, i), values in changes.items():
                if owner == "payload":
                    payload = dataclasses.replace(payload, **values)
                elif owner == "link":
                    links[i] = dataclasses.replace(links[i], **values)
                else:
                    joints[i] = dataclasses.replace(joints[i], **values)
        except FieldError as exc:  # name it by its flat key
            owner, i = next((o, i) for (o, i), v in changes.items() if exc.field in v)
            stem = field_key(exc.field)
            raise FieldError("ArmParameters", stem if owner == "payload" else f"{stem}{i + 1}",
                             exc.reason) from None
        return ArmParameters(links, joints, payload, gravity)

    @classmethod
    def from_mapping(cls, values: dict, *, where: str = "params",
                     base: "ArmParameters | None" = None) -> "ArmParameters":
        """A parameter table: a whole arm (``links``, ``joints``, ``payload``,
        ``gravity``: a resolved scenario's form), else ``base`` (default: the default
        arm), then its flat keys changed; an unknown key or a bad value is a ValueError
        naming ``where.key``."""
        whole = {k: v for k, v in values.items() if k in _STRUCTURE}
        flat = {k: v for k, v in values.items() if k not in _STRUCTURE}
        try:
            if "links" in whole:
                base = arm_from_table(whole, where=where)
            else:
                base = cls() if base is None else base
                flat = {**whole, **flat}
            return base.replace(**flat)
        except FieldError as exc:
            raise ValueError(f"{where}.{exc.field} {exc.reason}") from None
        except ArmFileError as exc:
            raise ValueError(str(exc)) from None

    # --- the physics a plant or a law asks of the description ------------------------------
    @property
    def n_links(self) -> int:
        return len(self.links)

    def modes(self) -> tuple[int, ...]:
        """Each link's assumed modes (0: rigid)."""
        return tuple(link.modes for link in self.links)

    def tip_load(self, i: int) -> tuple[float, float]:
        """Tip mass M_L [kg] and tip rotary inertia J_L [kg m²] of link ``i`` (from 0):
        the boundary loads of its clamped-mass eigenproblem — everything the link carries,
        as a rigid body straight out from its tip seen from the next joint's axis (the
        next hub, stators, outer links and payload); for the last link, the payload."""
        links = self.links
        if not 0 <= i < len(links):
            raise ValueError(f"link must be 0..{len(links) - 1}, got {i!r}")
        if i == len(links) - 1:
            return self.payload.mass, self.payload.inertia
        mass = links[i + 1].hub_mass + links[i].stator_mass
        inertia = links[i + 1].hub_inertia + links[i].stator_inertia
        d = 0.0  # distance from the next joint's axis to the current link's root
        for k in range(i + 1, len(links)):
            link = links[k]
            mass += link.mass
            inertia += link.root_inertia
            if d > 0:
                inertia += link.mass * d * (d + link.length)
            d += link.length
            if k < len(links) - 1:
                point = links[k].stator_mass + links[k + 1].hub_mass
                mass += point
                inertia += link.stator_inertia + links[k + 1].hub_inertia + point * d * d
        mass += self.payload.mass
        inertia += self.payload.inertia
        inertia += self.payload.mass * d**2
        return mass, inertia

    def tip_point_mass(self, i: int) -> float:
        """The point mass at link ``i``'s tip in its own dynamics: the next hub and the
        stator there, or the payload on the last link [kg]."""
        if i == len(self.links) - 1:
            return self.payload.mass
        return self.links[i + 1].hub_mass + self.links[i].stator_mass

    def rotor_inertias(self) -> tuple[float, ...]:
        """The rotary inertias in the order hub 1, link-1 tip (the motor-2 stator), hub 2,
        …, the last tip (the payload) [kg m²]."""
        out = []
        for i, link in enumerate(self.links):
            tip = self.payload.inertia if i == len(self.links) - 1 else link.stator_inertia
            out += [link.hub_inertia, tip]
        return tuple(out)

    def joints_text(self) -> str:
        """The joint physics of this arm in words ("" for ideal joints), e.g. "joint 1:
        friction 0.3/0.4 N m, viscous 0.2 N m s/rad; drive 1e+04 N m/rad, rotor 0.1 kg m²
        (encoder on the motor)"."""
        parts = []
        for i, j in enumerate(self.joints):
            items = []
            if j.static_friction > 0:
                items.append(f"friction {j.coulomb:g}/{j.static_friction:g} N m")
            if j.viscous > 0:
                items.append(f"viscous {j.viscous:g} N m s/rad")
            if j.has_drive:
                items.append(f"drive {j.gear_stiffness:g} N m/rad, rotor {j.rotor_inertia:g} "
                             "kg m²" + (f", backlash {j.backlash:g} rad" if j.backlash else "")
                             + " (encoder on the motor)")
            if j.torque_time_constant > 0:
                items.append(f"torque lag {j.torque_time_constant:g} s")
            if items:
                parts.append(f"joint {i + 1}: " + ", ".join(items))
        return "; ".join(parts)

    def without(self, *effects: str) -> "ArmParameters":
        """A copy with the joint ``effects`` (`JOINT_EFFECTS`: "friction", "drive",
        "bandwidth") switched off on every joint."""
        off = {name: 0.0 for effect in effects for name in JOINT_EFFECTS[effect]}
        return ArmParameters(self.links, tuple(dataclasses.replace(j, **off) for j in self.joints),
                             self.payload, self.gravity)


class ArmFileError(ValueError):
    """An arm description that is not one: the message names the file or table and the
    key."""


def _at(where: str, key: str) -> str:
    """``key`` of the table ``where`` names: "FILE.toml: key", or a dotted "arm.key"."""
    return f"{where}: {key}" if where.endswith(".toml") else f"{where}.{key}"


def _part(cls, declared, table, where: str, part: str):
    """A `Link`, `Joint` or `Payload` from its table, ``part`` naming it ("link 1")."""
    if not isinstance(table, dict):
        raise ArmFileError(f"{_at(where, part)}: must be a table, got {table!r}")
    names = [f.name for f in declared]
    for key in table:
        if key not in names:
            raise ArmFileError(f"{_at(where, part)}: {key}: unknown key{suggestion(key, names)} "
                               f"(allowed: {', '.join(names)})")
    try:
        return cls(**table)
    except FieldError as exc:
        raise ArmFileError(f"{_at(where, part)}: {exc.field} {exc.reason}") from None


def arm_from_table(table: dict, *, where: str = "arm") -> ArmParameters:
    """The arm an arm table describes (module docstring); `ArmFileError` naming
    ``where`` and the key for anything else."""
    if not isinstance(table, dict):
        raise ArmFileError(f"{where}: must be a table, got {table!r}")
    for key in table:
        if key not in ARM_KEYS:
            raise ArmFileError(f"{_at(where, key)}: unknown key{suggestion(key, ARM_KEYS)} "
                               f"(allowed: {', '.join(ARM_KEYS)})")
    links = table.get("links")
    if not isinstance(links, list) or not links:
        raise ArmFileError(f"{_at(where, 'links')}: must be 1 to 4 link tables ([[links]]), "
                           f"got {links!r}")
    parts = [_part(Link, LINK_FIELDS, t, where, f"link {i + 1}") for i, t in enumerate(links)]
    joints = table.get("joints")
    if joints is not None:
        if not isinstance(joints, list) or len(joints) != len(links):
            raise ArmFileError(f"{_at(where, 'joints')}: must be one table per link "
                               f"({len(links)}; empty for an ideal joint), got "
                               f"{len(joints) if isinstance(joints, list) else joints!r}")
        joints = [_part(Joint, JOINT_FIELDS, t, where, f"joint {i + 1}")
                  for i, t in enumerate(joints)]
    payload = _part(Payload, PAYLOAD_FIELDS, table.get("payload", {}), where, "payload")
    try:
        return ArmParameters(parts, joints, payload, table.get("gravity", (0.0, 0.0)))
    except FieldError as exc:
        raise ArmFileError(f"{_at(where, _path(exc.field, len(links)))} {exc.reason}") from None


def _path(key: str, n_links: int) -> str:
    """Where a flat key lives in an arm table: ``EI2`` → "link 2: bending_stiffness (EI2)"."""
    found = flat_key_field(key, n_links)
    if found is None:
        return key
    owner, i, f = found
    return (f"payload: {f.name} ({key})" if owner == "payload"
            else f"{owner} {i + 1}: {f.name} ({key})")


def arm_to_table(arm: ArmParameters) -> dict:
    """The arm table of ``arm`` (what `arm_from_table` reads back to an equal arm)."""
    def plain(part, declared):
        return {f.name: getattr(part, f.name) for f in declared}
    table = {"gravity": list(arm.gravity),
             "links": [plain(link, LINK_FIELDS) for link in arm.links],
             "payload": plain(arm.payload, PAYLOAD_FIELDS)}
    if any(j != Joint() for j in arm.joints):
        table["joints"] = [plain(j, JOINT_FIELDS) for j in arm.joints]
    return table


@functools.cache
def _default_arm() -> ArmParameters:
    """The default arm, from its shipped file (the named arm "default")."""
    text = (resources.files(__package__) / "named" / "default.toml").read_text(encoding="utf-8")
    return arm_from_table(tomllib.loads(text), where="arm 'default'")
