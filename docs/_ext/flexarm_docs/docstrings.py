"""The numpydoc sections of a docstring, read without Sphinx: the generators and
``tests/test_docs.py`` (which runs without the docs extra) read the same entries."""
from __future__ import annotations

import inspect
import re
from typing import NamedTuple


class Entry(NamedTuple):
    name: str
    type: str
    desc: str


def sections(obj) -> dict[str, list[Entry]]:
    """Section title → its entries (``name : type`` lines and their indented text)."""
    lines = (inspect.getdoc(obj) or "").splitlines()
    out: dict[str, list[Entry]] = {}
    current = None
    for i, line in enumerate(lines):
        if i + 1 < len(lines) and re.fullmatch(r"-{3,}", lines[i + 1].strip()) \
                and line.strip() and not line.startswith(" "):
            current = out.setdefault(line.strip(), [])
            continue
        if current is None or re.fullmatch(r"-{3,}", line.strip()):
            continue
        if line and not line.startswith(" "):
            name, _, type_ = line.partition(" : ")
            current.append(Entry(name.strip(), type_.strip(), ""))
        elif line.strip() and current:
            last = current[-1]
            current[-1] = last._replace(desc=f"{last.desc} {line.strip()}".strip())
    return out


def entries(obj, section: str) -> list[Entry]:
    """The entries of one section, a ``a, b : type`` line split into one per name."""
    return [Entry(name.strip(), e.type, e.desc) for e in sections(obj).get(section, [])
            for name in e.name.split(",")]
