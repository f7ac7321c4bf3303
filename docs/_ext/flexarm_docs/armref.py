"""The fields of an arm file and the shipped arms, generated from their declarations
(`reduced_model.arm.fields`) and files (`reduced_model.named_arms`)."""
from __future__ import annotations

from .rst import list_table, literal


def _fields(fields, numbered: bool = True) -> str:
    """A table of ``fields``; ``numbered``: their flat keys take the link's or joint's
    number i (``EI2``), else they are whole (the payload's ``Mp``)."""
    rows = [[literal(f.name), f.unit or "—", f.meaning,
             literal(f.key) + ("\\ *i*" if numbered else ""), f.typical] for f in fields]
    return list_table(["field", "unit", "meaning", "flat key", "typical"], rows,
                      widths=[18, 8, 40, 12, 22])


def render(docs) -> str:
    from reduced_model import named_arms
    from reduced_model.arm.fields import JOINT_FIELDS, LINK_FIELDS, PAYLOAD_FIELDS
    arms = list_table(["name", "what it is"],
                      [[literal(name), text] for name, text in named_arms().items()],
                      widths=[22, 78])
    return ("Each ``[[links]]`` table\n" + "~" * 24 + "\n\n" + _fields(LINK_FIELDS)
            + "Each ``[[joints]]`` table (optional: ideal joints without it)\n" + "~" * 61
            + "\n\n" + _fields(JOINT_FIELDS)
            + "The ``[payload]`` table\n" + "~" * 23 + "\n\n"
            + _fields(PAYLOAD_FIELDS, numbered=False)
            + "The shipped arms\n" + "~" * 16 + "\n\n" + arms)
