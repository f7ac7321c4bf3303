"""What `flexarm validity` stores (validity.json, `validity.validity_analysis`) and how a
report reads it back: its channels, its ν-gap views and its schema, apart from the
analysis, so that reading the file loads none of python-control and scipy.signal."""
from __future__ import annotations

from pathlib import Path

from ..run.results import read_json

__all__ = ["GAP_VIEWS", "channels", "load_validity"]


def channels(modes_per_link) -> tuple[tuple[str, str], ...]:
    """(input, output) channels of the frequency responses of an arm with
    ``modes_per_link``: τ_i → θ_i of every joint, then τ_i → w_i(L_i) of every flexible
    link (a rigid link's tip does not deflect)."""
    links = range(1, len(modes_per_link) + 1)
    return (tuple((f"tau{i}", f"theta{i}") for i in links)
            + tuple((f"tau{i}", f"tip_defl{i}") for i, m in zip(links, modes_per_link) if m))

#: The views of the reduced and FE plants whose ν-gap the analysis computes.
GAP_VIEWS = ("theta", "tip", "loop")

_NUMBER = (int, float)
_CURVES = {str: [_NUMBER]}  # "IN->OUT": |H| per frequency, the arm's `channels`
#: What the report reads of validity.json (`validation.run.results.read_json`).
_SCHEMA = {
    "arms": [{"arm": str, "Ts": _NUMBER, "modes": [int], "truth": str, "left_out": [str],
              "frequencies_hz": [_NUMBER],
              "responses": [{"theta2": _NUMBER, "reduced": _CURVES, "fe": _CURVES}],
              "gaps": [{"theta2": _NUMBER, **{k: _NUMBER for v in GAP_VIEWS
                                              for k in (v, f"{v}_peak_hz")}}]}],
    "cases": [{"case": str, "plant": str, "arm": str, "predicted_s": _NUMBER, "mesh": str,
               "predicted_fine_s": _NUMBER, "mesh_fine": str, "certified_s": _NUMBER,
               "certificate": [dict], "largest_stable_s": _NUMBER,
               "first_unstable_s": _NUMBER, "limit_low_s": _NUMBER,
               "limit_high_s": _NUMBER, "limit_verdict": str, "in_bracket": str, "sound": str,
               "conservatism": _NUMBER, "note": str, "evidence": str}],
}


def load_validity(folder) -> dict | None:
    """The stored analysis of a validity folder (validity.json), or None; ValueError
    naming the file and key if it is not what `flexarm validity` writes."""
    path = Path(folder) / "validity.json"
    if not path.is_file():
        return None
    return read_json(path, _SCHEMA)
