"""The report's bottom line: sentences a reviewer can quote, computed from the stored
results — first what became of the paper's claims on each plant and arm (the truth plant
first), the verdicts that cannot be given named with what stops them; then how many runs
completed, diverged and failed (the mesh/step checks counted apart from the runs they
check) and where the divergences and failures are (which arm, control period and plant),
the divergences the stability map foresees said to be expected.  A calibration's folder says
what was fitted and the verdict on the model instead."""
from __future__ import annotations

from collections import Counter

from ..run.plants import is_truth

__all__ = ["bottom_line", "claims_sentences", "UNDECIDED"]

#: What stops a claim's verdict, by the verdict given instead (`verdicts.claims.Verdict`).
UNDECIDED = {
    "not converged": "the truth plant's value moved when its mesh and step were refined",
    "window-sensitive": "the verdict changes with the analysis window",
    "mesh not checked": "the truth plant's mesh/step checks were not run",
    "diverged": "the run diverged",
    "failed": "the run failed",
    "not run": "the claim's run is not in the folder",
}


def _plural(n: int, word: str) -> str:
    return f"{n} {word if n == 1 else word + 's'}"


def _places(runs) -> list[tuple[int, str]]:
    """(count, "the table1 arm at Ts = 1 ms, truth plant (Exudyn)") per arm and control
    period, most first."""
    counts = Counter((r.arm, r.Ts) for r in runs)  # the row's columns: no scenario decoded
    out = []
    for (arm, Ts), n in counts.most_common():
        plants = sorted({r.plant_label for r in runs if (r.arm, r.Ts) == (arm, Ts)})
        period = f"at Ts = {1e3 * Ts:g} ms" if Ts is not None else "(Ts not given)"
        out.append((n, f"the {arm} arm {period}, {' and '.join(plants)}"))
    return out


def _where(runs, what: str) -> str:
    """"all 44 divergences are on the table1 arm at Ts = 1 ms, …" or "the 5 …: 3 on …;
    2 on …" (three places at most, then how many more)."""
    places = _places(runs)
    if len(places) == 1:
        return f"{'all ' if len(runs) > 1 else ''}{_plural(len(runs), what)} " \
               f"{'are' if len(runs) > 1 else 'is'} on {places[0][1]}"
    shown = "; ".join(f"{n} on {place}" for n, place in places[:3])
    more = f"; {len(places) - 3} more places" if len(places) > 3 else ""
    return f"the {_plural(len(runs), what)}: {shown}{more}"


def _counted(runs) -> str:
    count = Counter(r.status for r in runs)
    return f"{count['ok']} completed, {count['diverged']} diverged, {count['failed']} failed"


def _runs_sentence(runs, checks) -> str:
    text = f"{_plural(len(runs), 'run')}: {_counted(runs)}"
    if checks:
        text += (f"; their {_plural(len(checks), 'mesh/step-check run')} (the truth-plant "
                 f"runs again on refined meshes and steps): {_counted(checks)}")
    return text + "."


def _stops_sentence(runs, checks, expected: frozenset = frozenset()) -> str:
    diverged = [r for r in runs if r.status == "diverged"]
    foreseen = [r for r in diverged if r.run_id in expected] if expected else []
    parts = []
    if foreseen:
        parts.append(f"{'all' if len(foreseen) == len(diverged) else len(foreseen)} of the "
                     f"{_plural(len(diverged), 'divergence')} "
                     f"{'are' if len(foreseen) > 1 else 'is'} expected: at or beyond the "
                     "stability map's first divergence of their arm and plant")
        diverged = [r for r in diverged if r.run_id not in expected]
        if diverged:
            parts.append(_where(diverged, "unexpected divergence"))
    elif diverged:
        parts.append(_where(diverged, "divergence"))
    parts += [_where([r for r in group if r.status == s], word)
              for group, s, word in ((runs, "failed", "failure"),
                                     (checks, "failed", "failed check"))
              if any(r.status == s for r in group)]
    if not parts:
        return ""
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


def claims_sentences(columns) -> list[str]:
    """The bottom line's answer: per plant (the truth plant first) and arm, one sentence
    counting the paper's claims that hold and fail, the ones not given named with what
    stops them.

    Parameters
    ----------
    columns : list of Column
        The claims' columns (`validation.verdicts.claims.claim_columns`).

    Returns
    -------
    list of str
        One sentence per plant and arm that has a verdict.
    """
    from ..verdicts.claims import CLAIMS
    lines = []
    for role, name in (("truth", "the truth plant"), ("reduced", "the reduced model")):
        for arm in dict.fromkeys(c.arm for c in columns):
            verdicts = Counter(v.verdict for c in columns if c.arm == arm and is_truth(
                next(iter(c.runs.values())).config) == (role == "truth")
                for v in c.verdicts.values() if v.verdict != "n/a")
            if not verdicts:
                continue
            count = sum(c.arm == arm and is_truth(next(iter(c.runs.values())).config)
                        == (role == "truth") for c in columns)
            text = (f"On {name}, {arm} arm ({_plural(count, 'column')} × the paper's "
                    f"{len(CLAIMS)} claims): {verdicts['holds']} verdicts hold and "
                    f"{verdicts['fails']} fail")
            undecided = [f"{verdicts[v]} {v} ({meaning})" for v, meaning in UNDECIDED.items()
                         if verdicts[v]]
            if undecided:
                total = sum(verdicts[v] for v in UNDECIDED)
                text += f"; {total} are not given: " + ", ".join(undecided)
            lines.append(text + ".")
    return lines


def _calibration_sentence(calibration: dict) -> str:
    fitted = "; ".join(f"{row[0]} = {row[1]}" + (f" ({calibration['interval']} {row[3]})"
                                                   if row[3] != "—" else " (not identifiable)")
                       for row in calibration["rows"])
    verdict = calibration["adequacy"]["verdict"] if calibration.get("adequacy") else \
        "not judged"
    return f"flexarm calibrate fitted {fitted}. The verdict on the model: {verdict}."


def bottom_line(runs, checks, columns, calibration: dict | None = None, *,
                expected: frozenset = frozenset()) -> list[str]:
    """The report's first sentences.

    Parameters
    ----------
    runs : list of StoredRun
        The runs the report shows (fresh, verified; no mesh/step checks).
    checks : list of StoredRun
        The mesh/step-check runs of those runs.
    columns : list of Column
        The claims' columns (`validation.verdicts.claims.claim_columns`), or [].
    calibration : dict, optional
        The report's calibration section (`validation.report.calibration`).
    expected : set of str, optional
        The ids of the runs whose divergence the stability map foresees
        (`validation.verdicts.claims.beyond_every_limit`).

    Returns
    -------
    list of str
        Sentences, each complete on its own: the claims per plant and arm first (the
        answer), then the runs counted and where they stopped.

    Examples
    --------
    >>> from types import SimpleNamespace as Run
    >>> runs = [Run(status=s, arm="table1", Ts=1e-3, plant_label="reduced plant")
    ...         for s in ("ok", "diverged", "diverged")]
    >>> print("\\n".join(bottom_line(runs, [], [])))
    3 runs: 1 completed, 2 diverged, 0 failed.
    All 2 divergences are on the table1 arm at Ts = 1 ms, reduced plant.
    """
    lines = claims_sentences(columns) if columns else []
    if runs:
        lines += [_runs_sentence(runs, checks), _stops_sentence(runs, checks, expected)]
    if calibration:
        lines.append(_calibration_sentence(calibration))
    return [line for line in lines if line]

