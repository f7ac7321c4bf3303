"""The arm description: links, joints, payload and gravity of a planar serial arm, each
field declared once (`reduced_model.arm.fields`), read from TOML (`reduced_model.arm.files`)."""
from .description import ARM_KEYS, ArmFileError, ArmParameters, arm_from_table, arm_to_table
from .fields import (JOINT_EFFECTS, JOINT_FIELDS, LINK_FIELDS, MAX_LINKS, MAX_MODES,
                     PAYLOAD_FIELDS, Field)
from .files import named_arm, named_arms, read_arm
from .parts import FieldError, Joint, Link, Payload, flat_key_field

__all__ = ["ArmParameters", "FieldError", "Joint", "Link", "Payload", "flat_key_field",
           "JOINT_EFFECTS", "JOINT_FIELDS", "LINK_FIELDS", "MAX_LINKS", "MAX_MODES",
           "PAYLOAD_FIELDS", "Field", "ARM_KEYS", "ArmFileError", "arm_from_table",
           "arm_to_table", "named_arm", "named_arms", "read_arm"]
