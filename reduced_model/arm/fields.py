"""Every field of an arm description, declared once: its name, the two-link key users
know, its unit, meaning, allowed range, typical values and the joint effect it belongs
to.  The checks (`reduced_model.arm.description`), the flat keys (``EI1``,
``coulomb2``), the kernels' packing, the calibration priors and the docs' tables are
derived from these declarations."""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Field", "LINK_FIELDS", "JOINT_FIELDS", "PAYLOAD_FIELDS", "JOINT_EFFECTS",
           "MAX_LINKS", "MAX_MODES"]

#: The largest arm described: 4 links (each with its joint at the root).
MAX_LINKS = 4
#: Assumed modes of a flexible link, 1..MAX_MODES (0: a rigid link).
MAX_MODES = 4


@dataclass(frozen=True)
class Field:
    """One field of a link, a joint or the payload.

    Parameters
    ----------
    name : str
        The field's name in an arm file and on the Python objects (``bending_stiffness``).
    key : str
        The flat key's stem (``EI``: ``EI1`` is link 1's; the payload's keys are whole,
        ``Mp``).
    unit : str
        SI unit ("" for a count).
    meaning : str
        One line for the docs and messages.
    positive : bool
        Must be > 0 (else >= 0).
    integer : bool
        A whole number (``modes``).
    maximum : float
        The largest value allowed.
    effect : str or None
        The joint effect (attribution factor) a joint field switches on: "friction",
        "drive" or "bandwidth".
    typical : str
        Typical values, in words (docs, and the hint of a calibration without a start).
    example : float
        A typical value (a calibration's example start).
    bounds : (float, float)
        Wide typical bounds (a calibration's example bounds).
    """

    name: str
    key: str
    unit: str
    meaning: str
    positive: bool = False
    integer: bool = False
    maximum: float = math.inf
    effect: str | None = None
    typical: str = ""
    example: float = 0.0
    bounds: tuple[float, float] = (0.0, math.inf)

    def check(self, value) -> str:
        """Why ``value`` cannot be this field's ("" when it can)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be a number, got {value!r}"
        if not math.isfinite(value):
            return f"must be finite, got {value!r}"
        if self.integer and value != int(value):
            return f"must be a whole number, got {value!r}"
        if self.positive and value <= 0.0:
            return f"must be > 0, got {value!r}"
        if value < 0.0:
            return f"must be >= 0, got {value!r}"
        if value > self.maximum:
            return f"must be <= {self.maximum:g}, got {value!r}"
        return ""


LINK_FIELDS = (
    Field("length", "L", "m", "length of the link", positive=True,
          typical="0.3-1 m for a lab arm", example=0.5),
    Field("mass_per_length", "rho", "kg/m", "mass per length of the link", positive=True,
          typical="0.2-2 kg/m for an aluminium strip or tube", example=1.0),
    Field("bending_stiffness", "EI", "N m²", "bending stiffness EI (a flexible link needs it; "
          "a rigid link takes none)", typical="1-100 N m² for a lab link", example=10.0,
          bounds=(0.1, 1e3)),
    Field("bending_damping", "bending_damping", "N m² s",
          "Kelvin-Voigt bending damping d (the bending moment is EI w'' + d ẇ'')",
          typical="1e-4-1e-2 N m² s (ζ = π f d/EI)", example=2e-3, bounds=(0.0, 0.1)),
    Field("modes", "modes", "", "assumed modes of the link in the reduced model (0: a rigid "
          "link)", integer=True, maximum=MAX_MODES, typical="2 (the paper's)", example=2),
    Field("hub_mass", "mh", "kg", "mass of the hub (motor rotor) at the link's root",
          typical="0.1-2 kg", example=1.0),
    Field("hub_inertia", "Jh", "kg m²", "inertia of the hub at the link's root",
          typical="0.01-1 kg m²", example=1.0),
    Field("stator_mass", "stator_mass", "kg", "mass of the next joint's motor stator, "
          "rigidly at the link's tip (none on the last link)", typical="0-1 kg", example=0.0),
    Field("stator_inertia", "stator_inertia", "kg m²", "inertia of that stator (the next "
          "joint's friction and drive act on it)", typical="1e-3-1e-2 kg m²", example=0.01),
)

JOINT_FIELDS = (
    Field("coulomb", "coulomb", "N m", "Coulomb (sliding) friction", effect="friction",
          typical="0.1-1 N m at the output of a small harmonic drive", example=0.3,
          bounds=(0.0, 2.0)),
    Field("breakaway", "breakaway", "N m", "static friction (0: equal to the Coulomb "
          "level, otherwise at least that)", effect="friction",
          typical="1-1.5x the Coulomb level", example=0.4, bounds=(0.0, 2.0)),
    Field("stribeck_velocity", "stribeck_velocity", "rad/s", "Stribeck velocity: the "
          "friction falls from the breakaway to the Coulomb level as exp(-|v|/v_s)",
          effect="friction", typical="1e-3-0.05 rad/s", example=0.01, bounds=(1e-4, 0.1)),
    Field("viscous", "viscous", "N m s/rad", "viscous friction", effect="friction",
          typical="0.05-1 N m s/rad", example=0.2, bounds=(0.0, 2.0)),
    Field("gear_stiffness", "gear_stiffness", "N m/rad", "torsional stiffness of the drive "
          "between motor and hub (0: a rigid joint)", effect="drive",
          typical="1e3-5e4 N m/rad", example=1e4, bounds=(1e2, 1e6)),
    Field("gear_damping", "gear_damping", "N m s/rad", "damping of that compliance (in "
          "contact)", effect="drive", typical="a few % of critical", example=5.0,
          bounds=(0.0, 50.0)),
    Field("rotor_inertia", "rotor_inertia", "kg m²", "motor rotor inertia reflected to the "
          "link side (a drive needs it)", effect="drive",
          typical="0.01-1 kg m^2 reflected to the link side", example=0.1, bounds=(1e-3, 10.0)),
    Field("backlash", "backlash", "rad", "lost motion of the drive (a dead zone of "
          "±backlash/2)", effect="drive", typical="< 3e-4 rad", example=2e-4,
          bounds=(0.0, 1e-3)),
    Field("torque_time_constant", "torque_time_constant", "s", "time constant of the "
          "motor's current (torque) loop (0: ideal)", effect="bandwidth",
          typical="1e-4-2e-3 s", example=3e-4, bounds=(0.0, 5e-3)),
)

PAYLOAD_FIELDS = (
    Field("mass", "Mp", "kg", "payload mass at the last link's tip", typical="0-1 kg",
          example=0.1, bounds=(0.0, 2.0)),
    Field("inertia", "Jp", "kg m²", "payload inertia", typical="0-1e-2 kg m²",
          example=5e-4),
)

#: The joint effects (attribution factors), each with the joint fields that switch it on.
JOINT_EFFECTS = {effect: tuple(f.name for f in JOINT_FIELDS if f.effect == effect)
                 for effect in ("friction", "drive", "bandwidth")}
