"""Rendering from data: one Jinja2 template per output format (``validation/templates``).

Tables are built as plain data (lists of rows of values) by the modules that compute
them; the templates only lay them out.  Markdown cells are escaped with the ``md``
filter (a ``|`` inside a cell would split it), HTML by Jinja2's autoescaping.
"""
from __future__ import annotations

import math

import jinja2

__all__ = ["environment", "render", "fmt_number", "md_cell", "display_unit", "folded",
           "folded_text", "FOLD_AT"]

#: SI unit → (factor, unit) a reader expects for the small values a report shows.
_DISPLAY = {"rad": (1e3, "mrad"), "m": (1e3, "mm"), "rad/s": (1e3, "mrad/s"),
            "m/s": (1e3, "mm/s")}


def display_unit(unit: str) -> tuple[float, str]:
    """(factor, unit) to show a value given in ``unit``: mrad for rad, mm for m, the
    same for rates; any other unit unchanged (factor 1)."""
    return _DISPLAY.get(unit, (1.0, unit))


def fmt_number(value, digits: int = 3) -> str:
    """A number for a table: 3 significant digits, "" for missing, "∞" for infinite."""
    if value is None:
        return ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if math.isnan(value):
        return ""
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    return f"{value:.{digits}g}"


#: A detail longer than this [characters] is folded away in the HTML report (a cell's
#: list of numbers: every mesh's value, the vibration per window).
FOLD_AT = 60


def folded(text: str, detail: str):
    """A table cell: ``text`` with ``detail`` in brackets, or, if the detail is longer than
    `FOLD_AT`, ``{"text", "detail", "full"}``: the HTML report shows the detail on demand,
    the markdown the ``full`` text."""
    if not detail:
        return text
    full = f"{text} ({detail})"
    return full if len(detail) <= FOLD_AT else {"text": text, "detail": detail, "full": full}


def folded_text(text: str):
    """`folded` of a sentence longer than `FOLD_AT`, split at its first ": ", " against "
    or " (": "converged against ANCF 8 el/link, …" → "converged" + "against ANCF 8 …"."""
    if len(text) <= FOLD_AT:
        return text
    cuts = [(text.find(sep), sep) for sep in (": ", " against ", " (") if sep in text]
    if not cuts:
        return text
    at, sep = min(cuts)
    detail = text[at:].removeprefix(": ").strip()
    if sep == " (" and detail.startswith("(") and detail.endswith(")"):
        detail = detail[1:-1]
    return {"text": text[:at], "detail": detail, "full": text}


def md_cell(value) -> str:
    """Text safe inside a markdown table cell: pipes escaped, no line breaks; a `folded`
    cell with its detail in brackets."""
    if isinstance(value, dict):
        value = value["full"]
    text = fmt_number(value) if isinstance(value, float) else str(value)
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ").replace("\r", " ")


_ENV: dict[bool, jinja2.Environment] = {}


def environment(html: bool) -> jinja2.Environment:
    if html not in _ENV:
        env = jinja2.Environment(
            loader=jinja2.PackageLoader("validation.report", "templates"),
            autoescape=html, trim_blocks=True, lstrip_blocks=True,
            undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
        env.filters["num"] = fmt_number
        env.filters["md"] = md_cell
        _ENV[html] = env
    return _ENV[html]


def render(template: str, **data) -> str:
    """Render ``templates/<template>`` with ``data`` (HTML-escaped for .html templates)."""
    return environment(template.endswith(".html.j2")).get_template(template).render(**data)
