"""The arms side by side, for a folder whose runs span several arms (e.g.
``campaigns/arms.toml``): one sentence per arm and plant first — how each system tracks
there, or that it did not complete —, then a table of each arm and system on both
plants: the tracking error after the transient, the residual vibration and the
observer's angle error against the encoder's own.  Each value is the largest over the
arm's joints (links); the requirements a user states are judged in their own section."""
from __future__ import annotations

from .render import fmt_number
from .run_tables import table
from .summary import numbered

__all__ = ["arms_answers", "arms_table"]

#: (metric key prefix, column, scale to the display unit) of the side-by-side table.
_COLUMNS = (("track_rms_", "tracking error RMS [mrad]", 1e3),
            ("vib_rms_", "vibration RMS [mm]", 1e3),
            ("est_to_noise_theta", "angle estimate ÷ encoder error", 1.0))


def _system(run) -> str:
    return run.name.split("/")[-1]


def _worst(run, prefix: str) -> float | None:
    values = numbered(run.metrics, prefix) if run.status == "ok" else []
    return max(values) if values else None


def _by_arm(runs) -> dict:
    arms: dict[str, dict] = {}
    for r in runs:
        arms.setdefault(r.arm, {}).setdefault(_system(r), {})[r.role] = r
    return arms


def arms_answers(runs) -> list[str]:
    """One sentence per arm and plant ([] for a folder of one arm): each system's
    tracking error RMS after the transient (the worst joint), or how it stopped."""
    arms = _by_arm(runs)
    if len(arms) < 2:
        return []
    lines = []
    for arm, systems in arms.items():
        for role, plant in (("truth", "truth plant"), ("reduced", "reduced model")):
            parts = []
            for system, by_role in sorted(systems.items()):
                run = by_role.get(role)
                if run is None:
                    continue
                if run.status != "ok":
                    parts.append(f"{system} {run.status} at {run.end_time:g} s")
                    continue
                value = _worst(run, "track_rms_")
                parts.append(f"{system} {fmt_number(1e3 * value)} mrad" if value is not None
                             else f"{system} —")
            if parts:
                lines.append(f"{arm} arm, {plant}: tracking error RMS after the transient "
                             f"(worst joint) {'; '.join(parts)}.")
    return lines


def arms_table(runs) -> dict | None:
    """Each arm and system on both plants (None for a folder of one arm)."""
    arms = _by_arm(runs)
    if len(arms) < 2:
        return None
    head = ["arm", "system"] + [f"{name}: reduced / truth" for _, name, _ in _COLUMNS]
    rows, classes = [], []
    for arm, systems in arms.items():
        for system, by_role in sorted(systems.items()):
            cells = [arm, system]
            for prefix, _, scale in _COLUMNS:
                texts = []
                for role in ("reduced", "truth"):
                    run = by_role.get(role)
                    value = None if run is None else _worst(run, prefix)
                    texts.append("not run" if run is None else run.status.upper()
                                 if run.status != "ok" else "—" if value is None
                                 else fmt_number(scale * value))
                cells.append(" / ".join(texts))
            rows.append(cells)
            classes.append("" if all(r.status == "ok" for r in by_role.values())
                           else "diverged")
    return table(head, rows, classes)
