"""reStructuredText building blocks shared by the generators."""
from __future__ import annotations

import re

#: A unit in a docstring's meaning: the first ``[...]`` that is not a list, a literal or a
#: TOML array-of-tables name ("[s]", "[N m]", "[the state's unit]").
UNIT = re.compile(r"\s*(?<![\[`])\[([^\]\[`\d][^\]\[`]*)\](?!\])")


def split_unit(text: str) -> tuple[str, str]:
    """(text without its unit, the unit or "")."""
    unit = UNIT.search(text)
    return (UNIT.sub("", text, count=1), unit.group(1)) if unit else (text, "")


_LITERAL = re.compile(r"(``.*?``)")


def escape_bars(text: str) -> str:
    """``|x|`` (a magnitude, as the docstrings write it) as text, not a substitution
    reference: every ``|`` outside inline literals is escaped, except a line block's
    leading "| "."""
    parts = _LITERAL.split(text)
    for i in range(0, len(parts), 2):
        parts[i] = re.sub(r"(?!^\| )\|", r"\\|", parts[i], flags=re.M)
    return "".join(parts)


#: What a reader copies into a shell or a file: a flag ("--set", "-n", "--tier=short") or a
#: word with an "@" ("pbc+smo-paper@reduced", which docutils would link as an e-mail).
_COPIED = re.compile(r"(?<![\w`-])(--?[A-Za-z][\w.-]*(?:=[^\s,;)]+)?|[\w.+:-]+@[\w.+:-]*\w)")


def literal_words(text: str) -> str:
    """``text`` with its flags and its words holding an "@" as inline literals (outside
    the literals it has): as prose, "--set" would become "–set" (smart quotes) and
    "controller+observer@plant" a ``mailto:`` link."""
    parts = _LITERAL.split(text)
    for i in range(0, len(parts), 2):
        parts[i] = _COPIED.sub(r"``\1``", parts[i])
    return "".join(parts)


def heading(text: str, underline: str) -> str:
    return f"{text}\n{underline * len(text)}\n\n"


def literal(value) -> str:
    """A value as inline literal text (empty for an empty string)."""
    text = str(value)
    return f"``{text}``" if text else ""


def cell(text: str) -> list[str]:
    """The lines of a list-table cell (blank lines kept: a cell may hold paragraphs)."""
    lines = escape_bars(str(text)).strip().splitlines() or [""]
    return lines


def list_table(header: list[str], rows: list[list[str]], *, widths: list[int] | None = None,
               classes: str = "") -> str:
    """A ``list-table`` directive; cells are reStructuredText."""
    out = [".. list-table::", "   :header-rows: 1"]
    if widths:
        out.append(f"   :widths: {' '.join(map(str, widths))}")
    if classes:
        out.append(f"   :class: {classes}")
    out.append("")
    for row in [header, *rows]:
        for i, value in enumerate(row):
            lines = cell(value)
            out.append(f"   {'* -' if i == 0 else '  -'} {lines[0]}".rstrip())
            out += [f"       {line}".rstrip() for line in lines[1:]]
    return "\n".join(out) + "\n\n"
