"""Cost of an arm's number of links: a 5 s closed loop of the paper's PBC + sign SMO
(compiled) on the reduced plant of the paper's two-link arm and of the three-link arm,
side by side in one process.

Target (issue 57: no new per-step Python): the three-link loop ≤ 2 × the two-link one.
Times are this process's CPU time (`time.process_time`, best of 5 after a run that
compiles): on a shared machine wall time also counts the others' work.
"""
from __future__ import annotations

import time

import numpy as np

from _report import report, target
from validation.run.loop import run_scenario
from validation.run.scenario import scenario_from_mapping

#: The paper's arm (the scenario's default) and the three-link arm.
ARMS = ("default", "three-link")
DURATION = 5.0
REPEAT = 5


def closed_loop_seconds(arm: str) -> tuple[float, int]:
    """Best CPU time of ``DURATION`` s of the PBC + sign SMO on ``arm``'s reduced plant,
    from the reference; and the arm's number of coordinates."""
    s = scenario_from_mapping({"duration": DURATION, "initial_state": "reference",
                               "arm": arm, "observer": {"kind": "smo-paper"},
                               "plant": {"kind": "reduced"}})
    result = run_scenario(s)  # compile
    assert result.status == "ok", result.message
    best = np.inf
    for _ in range(REPEAT):
        t0 = time.process_time()
        result = run_scenario(s)
        best = min(best, time.process_time() - t0)
        assert result.status == "ok", result.message
    return best, len(result.names_with("xhat_")) // 2


def main():
    seconds, rows = {}, []
    for arm in ARMS:
        seconds[arm], coordinates = closed_loop_seconds(arm)
        rows.append({"arm": arm, "coordinates": coordinates, "seconds": seconds[arm]})
    ratio = seconds["three-link"] / seconds["default"]
    rows[-1] |= {"ratio": ratio} | target(ratio, "<=", 2.0)
    report("arms", rows, columns=["arm", "coordinates", "seconds", "ratio", "target", "met"],
           title=f"{DURATION:g} s closed loop PBC + SMO (compiled) on the reduced plant, "
                 f"CPU s, best of {REPEAT}")
    print(f"three-link / two-link = {ratio:.2f}: target <= 2 "
          + ("met" if ratio <= 2.0 else "MISSED"))


if __name__ == "__main__":
    main()
