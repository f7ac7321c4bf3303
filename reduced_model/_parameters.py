"""Physical parameters of the two-link lightweight arm (the paper's Table 1).

One `ArmParameters` object drives both plants (reduced model and Exudyn FE model), so
a mismatch between "true" and "nominal" arm is always an explicit choice.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields

__all__ = ["ArmParameters", "FieldError", "JOINT_EFFECTS"]


class FieldError(ValueError):
    """A bad value of one field of a parameter object; ``field`` names it, ``reason`` says
    what is wrong (configuration loaders prefix the field with its full path).

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
    EI1 — ArmParameters.EI1 must be > 0, got -1.0
    """

    def __init__(self, owner: str, field: str, reason: str) -> None:
        self.field, self.reason = field, reason
        super().__init__(f"{owner}.{field} {reason}")

# Fields that must be strictly positive (a zero length, density or stiffness is not an arm).
_POSITIVE = ("L1", "L2", "rho1", "rho2", "EI1", "EI2")

#: The arm's physics beyond flexibility, by effect (an attribution factor each): the
#: fields of each joint i = 1, 2 that switch it on (all 0: the effect is absent).
JOINT_EFFECTS = {
    "friction": ("coulomb", "breakaway", "stribeck_velocity", "viscous"),
    "drive": ("gear_stiffness", "gear_damping", "rotor_inertia", "backlash"),
    "bandwidth": ("torque_time_constant",),
}


@dataclass(frozen=True)
class ArmParameters:
    """Planar two-link flexible arm, SI units, horizontal plane (no gravity).

    Defaults are Table 1 of the paper plus two choices the paper leaves implicit, a motor-2
    stator inertia and structural damping (`table1` gives Table 1 alone).  Link i is a
    uniform Euler–Bernoulli beam clamped to hub i; hub 1 turns about the fixed base,
    hub 2 (the motor-2 *rotor*) on a revolute joint at the link-1 tip; the payload sits
    rigidly at the link-2 tip.

    Parameters
    ----------
    L1, L2 : float
        Link lengths [m].
    rho1, rho2 : float
        Link masses per length [kg/m].
    EI1, EI2 : float
        Link bending stiffnesses [N m²].
    Jh1, Jh2 : float
        Hub inertias [kg m²]: hub 1, and the motor-2 rotor.
    mh1, mh2 : float
        Hub masses [kg] (mh1 sits on the fixed axis and does not enter the planar
        dynamics).
    Mp : float
        Payload mass [kg].
    Jp : float
        Payload inertia [kg m²].
    stator_mass : float
        Motor-2 stator mass rigidly at the link-1 tip [kg] (0: Table 1's mh2 is the whole
        motor).
    stator_inertia : float
        Motor-2 stator inertia at the link-1 tip [kg m²], in addition to the rotor's Jh2
        (Notes).
    bending_damping1, bending_damping2 : float
        Kelvin–Voigt material damping of each link, as its bending damping d_i [N m² s]
        (Notes).
    coulomb1, coulomb2 : float
        Coulomb (sliding) friction of each joint [N m]; typical of a small harmonic drive
        0.1–1 N m at the output (*Joint physics* below).
    breakaway1, breakaway2 : float
        Static friction [N m]: a torque below it holds a joint at rest (stiction); 0
        means equal to the Coulomb level, otherwise at least that.  Typically 1–1.5× the
        Coulomb level.
    stribeck_velocity1, stribeck_velocity2 : float
        Stribeck velocity [rad/s]: the friction falls from the breakaway to the Coulomb
        level as exp(−|v| / v_s) (needed where breakaway > coulomb; 1e-3–0.05 rad/s).
    viscous1, viscous2 : float
        Viscous friction of each joint [N m s/rad] (0.05–1 for a harmonic drive at its
        output).
    gear_stiffness1, gear_stiffness2 : float
        Torsional stiffness of the drive between the motor (rotor) and the hub [N m/rad];
        0: a rigid joint (no drive dynamics).  Harmonic drives of 5–50 N m rated torque:
        1e3–5e4 N m/rad.
    gear_damping1, gear_damping2 : float
        Damping of that compliance [N m s/rad] (in contact only, where there is backlash).
    rotor_inertia1, rotor_inertia2 : float
        Motor rotor inertia reflected to the link side, N² J_rotor [kg m²] (needs a gear
        stiffness, and a gear stiffness needs it): 0.01–1 for a small motor behind a
        1:50–1:160 gear.
    backlash1, backlash2 : float
        Lost motion of the drive [rad], a dead zone of ±backlash/2 in the compliance
        (needs a gear stiffness); a harmonic drive has almost none (< 3e-4 rad, 1 arcmin).
    torque_time_constant1, torque_time_constant2 : float
        Time constant [s] of the motor's current (torque) loop, a first-order lag of the
        commanded torque; 0: ideal.  1/(2π · bandwidth): 1e-4–2e-3 s for 80 Hz–1.5 kHz.

    Notes
    -----
    *The stator.*  Default inertia 0.01 kg m² (1 % of Jh2: a ~1 kg housing of 0.1 m
    radius).  The motor-2 reaction torque acts on the link-1 tip; with no rotary inertia
    there, a sampled (1 kHz) joint-2 PD with Kd2 = 4 N m s/rad diverges within 10 ms on
    *both* plants, and damping alone does not cure it.  3e-3 kg m² is the smallest value
    measured to keep Kd2 = 4 and 6 stable on the reduced and the FE plant; 0.01 leaves a
    3× margin.  It lowers the locked frequencies by ≤ 0.4 % and adds a 13.7 Hz mode of
    the free arm (the stator turning with the link-1 tip slope).

    *The damping.*  The bending moment is EI w'' + d ẇ''.  The material's retardation
    time β_i = d_i / EI_i damps every strain of the link alike (bending, axial, shear), so
    every mode of the arm — bending and axial, on both plants — has the damping ratio
    ζ = π f β (stiffness-proportional damping).  Default 2e-3, β = 2e-4 s: ζ = 0.04 % at
    the 0.63 Hz locked mode, 0.14–0.38 % at the free arm's 2.2 and 6.1 Hz, 2 % at 34 Hz,
    33 % at the first axial mode (522 Hz); light structural damping of a metal link, not
    a measured value — calibrate it to your arm.  Exudyn gets d as ``bendingDamping`` and
    β EA (β GA) as its axial (shear) damping; the reduced model uses D = β_i·K per link.

    *Joint physics.*  Every field from ``coulomb1`` on is 0 by default: the arm of the
    paper, whose joints are ideal.  Both plants apply them the same way
    (``docs/theory/joints.rst``): friction acts between the hub and its base (the motor-2
    stator for joint 2) or, with a drive, between the rotor and the base; with a drive the
    motor torque turns the rotor, the compliance turns the hub, and the encoder reads the
    rotor.  Joint 2's friction and drive need a stator inertia (they act on it).  Typical
    values: Harmonic Drive AG's CSF/CSD catalogue (torsional stiffness, lost motion), the
    harmonic-drive identifications of Tuttle & Seering (IEEE Trans. Robotics and
    Automation 12(3), 1996) and Taghirad & Bélanger (J. Dyn. Sys. Meas. Control 120(4),
    1998); `lab` gives one set.

    The paper's Table 1 lists J01 = J02 = 0.0415 kg m²; that is ρL³/3 = 0.041667
    rounded.  Here it is derived (`J01`, `J02`), never stored, so it cannot disagree
    with ρ and L.
    """

    L1: float = 0.5
    L2: float = 0.5
    rho1: float = 1.0
    rho2: float = 1.0
    EI1: float = 10.0
    EI2: float = 10.0
    Jh1: float = 1.0
    Jh2: float = 1.0
    mh1: float = 1.0
    mh2: float = 1.0
    Mp: float = 0.1
    Jp: float = 0.0005
    stator_mass: float = 0.0
    stator_inertia: float = 0.01
    bending_damping1: float = 2e-3
    bending_damping2: float = 2e-3
    coulomb1: float = 0.0
    coulomb2: float = 0.0
    breakaway1: float = 0.0
    breakaway2: float = 0.0
    stribeck_velocity1: float = 0.0
    stribeck_velocity2: float = 0.0
    viscous1: float = 0.0
    viscous2: float = 0.0
    gear_stiffness1: float = 0.0
    gear_stiffness2: float = 0.0
    gear_damping1: float = 0.0
    gear_damping2: float = 0.0
    rotor_inertia1: float = 0.0
    rotor_inertia2: float = 0.0
    backlash1: float = 0.0
    backlash2: float = 0.0
    torque_time_constant1: float = 0.0
    torque_time_constant2: float = 0.0

    @classmethod
    def table1(cls) -> "ArmParameters":
        """The paper's Table 1 exactly: no stator inertia, no structural damping.  The
        published and the independent FE reference frequencies (`flexarm modes --table1`) are for this arm."""
        return cls(stator_inertia=0.0, bending_damping1=0.0, bending_damping2=0.0)

    @classmethod
    def lab(cls) -> "ArmParameters":
        """The default arm behind small harmonic drives (``arm = "lab"``): joint friction
        with stiction, gear compliance, reflected rotor inertia, a little lost motion and
        a 500 Hz current loop — mid-range values of the sources in *Joint physics* (the
        docs' theory page lists each value with its source)."""
        return cls(coulomb1=0.3, coulomb2=0.15, breakaway1=0.4, breakaway2=0.2,
                   stribeck_velocity1=0.01, stribeck_velocity2=0.01,
                   viscous1=0.2, viscous2=0.1,
                   gear_stiffness1=1.0e4, gear_stiffness2=5.0e3,
                   gear_damping1=5.0, gear_damping2=2.0,
                   rotor_inertia1=0.1, rotor_inertia2=0.05,
                   backlash1=2e-4, backlash2=2e-4,
                   torque_time_constant1=3.2e-4, torque_time_constant2=3.2e-4)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise FieldError("ArmParameters", f.name, f"must be a number, got {value!r}")
            if not math.isfinite(value):
                raise FieldError("ArmParameters", f.name, f"must be finite, got {value!r}")
            if f.name in _POSITIVE and value <= 0.0:
                raise FieldError("ArmParameters", f.name, f"must be > 0, got {value!r}")
            if value < 0.0:
                raise FieldError("ArmParameters", f.name, f"must be >= 0, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        for i in (1, 2):
            self._check_joint(i)

    def _check_joint(self, i: int) -> None:
        """The joint fields of joint ``i`` must describe a joint (FieldError naming one)."""
        get = lambda name: getattr(self, f"{name}{i}")  # noqa: E731
        def need(ok: bool, name: str, reason: str) -> None:
            if not ok:
                raise FieldError("ArmParameters", f"{name}{i}", reason)
        need(get("breakaway") == 0 or get("breakaway") >= get("coulomb"), "breakaway",
             f"must be 0 (= coulomb{i}) or >= coulomb{i} = {get('coulomb')!r}, got "
             f"{get('breakaway')!r}")
        need(get("breakaway") <= get("coulomb") or get("stribeck_velocity") > 0,
             "stribeck_velocity", f"must be > 0 where breakaway{i} > coulomb{i} (the "
             "friction falls from one to the other over it)")
        drive = get("gear_stiffness") > 0
        need(drive == (get("rotor_inertia") > 0), "rotor_inertia",
             f"must be > 0 where gear_stiffness{i} > 0 (a drive) and 0 where it is 0 (a "
             f"rigid joint), got {get('rotor_inertia')!r} with gear_stiffness{i} = "
             f"{get('gear_stiffness')!r}")
        for name in ("gear_damping", "backlash"):
            need(drive or get(name) == 0, name, f"needs a drive (gear_stiffness{i} > 0)")
        acting = [n for n in (*JOINT_EFFECTS["friction"], *JOINT_EFFECTS["drive"])
                  if get(n) > 0]
        need(i == 1 or not acting or self.stator_inertia > 0, acting[0] if acting else "",
             "needs a motor-2 stator inertia (stator_inertia > 0): joint 2's friction and "
             "drive act on the stator")

    # --- the joints ---------------------------------------------------------------------
    def static_friction(self, i: int) -> float:
        """Joint ``i``'s breakaway torque [N m]: the static level, at least the Coulomb
        level (0: no dry friction)."""
        return max(getattr(self, f"breakaway{i}"), getattr(self, f"coulomb{i}"))

    def has_drive(self, i: int) -> bool:
        """Whether joint ``i`` has a drive (gear compliance and rotor inertia)."""
        return getattr(self, f"gear_stiffness{i}") > 0

    def joints_text(self) -> str:
        """The joint physics of this arm in words ("" for ideal joints), e.g. "joint 1:
        friction 0.3/0.4 N m, viscous 0.2 N m s/rad; drive 1e+04 N m/rad, rotor 0.1 kg m²
        (encoder on the motor)"."""
        parts = []
        for i in (1, 2):
            get = lambda name: getattr(self, f"{name}{i}")  # noqa: E731
            items = []
            if self.static_friction(i) > 0:
                items.append(f"friction {get('coulomb'):g}/{self.static_friction(i):g} N m")
            if get("viscous") > 0:
                items.append(f"viscous {get('viscous'):g} N m s/rad")
            if self.has_drive(i):
                items.append(f"drive {get('gear_stiffness'):g} N m/rad, rotor "
                             f"{get('rotor_inertia'):g} kg m²"
                             + (f", backlash {get('backlash'):g} rad" if get("backlash") else "")
                             + " (encoder on the motor)")
            if get("torque_time_constant") > 0:
                items.append(f"torque lag {get('torque_time_constant'):g} s")
            if items:
                parts.append(f"joint {i}: " + ", ".join(items))
        return "; ".join(parts)

    def without(self, *effects: str) -> "ArmParameters":
        """A copy with the `JOINT_EFFECTS` ``effects`` (e.g. "friction") switched off."""
        return self.replace(**{f"{name}{i}": 0.0 for effect in effects
                               for name in JOINT_EFFECTS[effect] for i in (1, 2)})

    # --- derived quantities -------------------------------------------------------
    @property
    def m1(self) -> float:
        """Mass of link 1 [kg]."""
        return self.rho1 * self.L1

    @property
    def m2(self) -> float:
        """Mass of link 2 [kg]."""
        return self.rho2 * self.L2

    @property
    def J01(self) -> float:
        """Inertia of link 1 about its joint, ρ1 L1³/3 [kg m²] (Table 1 rounds to 0.0415)."""
        return self.rho1 * self.L1**3 / 3.0

    @property
    def J02(self) -> float:
        """Inertia of link 2 about its joint, ρ2 L2³/3 [kg m²]."""
        return self.rho2 * self.L2**3 / 3.0

    def tip_load(self, link: int) -> tuple[float, float]:
        """Tip mass M_L [kg] and tip rotary inertia J_L [kg m²] of link ``link`` (1 or 2).

        These are the boundary loads of the clamped-mass eigenproblem: for link 1 the
        whole of what it carries (hub 2, stator, link 2 and payload as a rigid body seen
        from the joint-2 axis), for link 2 the payload.
        """
        if link == 1:
            mass = self.mh2 + self.stator_mass + self.m2 + self.Mp
            inertia = self.Jh2 + self.stator_inertia + self.J02 + self.Jp + self.Mp * self.L2**2
            return mass, inertia
        if link == 2:
            return self.Mp, self.Jp
        raise ValueError(f"link must be 1 or 2, got {link!r}")

    # --- construction helpers -----------------------------------------------------
    def replace(self, **changes: float) -> "ArmParameters":
        """A copy with some fields changed (validated like the constructor)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise ValueError(f"unknown ArmParameters field(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_mapping(cls, values: dict, *, where: str = "params") -> "ArmParameters":
        """Build from a mapping; unknown keys are rejected with their full path."""
        known = {f.name for f in fields(cls)}
        for key in values:
            if key not in known:
                raise ValueError(
                    f"{where}.{key}: unknown parameter (allowed: {', '.join(sorted(known))})"
                )
        try:
            return cls(**values)
        except ValueError as exc:
            raise ValueError(str(exc).replace("ArmParameters.", f"{where}.")) from None
