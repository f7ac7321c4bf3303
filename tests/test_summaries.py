"""What the verdict commands print: verdicts counted and where the files are, never a
table; a verdict a failed run left missing is what makes the command exit 1, a failure
that decides nothing is counted."""
import math
from pathlib import Path
from types import SimpleNamespace

from validation.cli.summaries import claims_summary, stability_summary
from validation.report.summary import counted
from validation.verdicts.claims import CLAIMS, Verdict
from validation.verdicts.stability import Limit, StabilityCase, StabilityResult


def result(tested: dict, divergence: Limit, tracking: Limit, plant="exudyn", arm="table1"):
    case = StabilityCase("pd", plant, arm, {"controller": {"kind": "pd"},
                                            "observer": {"kind": "none"}})
    return StabilityResult(case, tested, divergence, tracking, math.nan)


def test_a_failure_above_a_limit_found_decides_nothing():
    """Table 1's arm on the truth plant diverges at 0.1 ms; the solver gives up at 10 ms
    (as in the paper reproduction): counted, no limit missing."""
    tested = {1e-4: ("diverged", "fast"), 1e-2: ("failed", "solver failed")}
    limit = Limit(math.nan, 1e-4, "diverged", "fast")
    lines, missing = stability_summary([result(tested, limit, limit)], Path("o/stability.md"),
                                       tolerance=0.01)
    assert missing == 0
    assert lines[0] == "stability map: 1 cases, 0 runs, bisected to 1.00% -> o/stability.md"
    assert any("1 run(s) failed above a limit already found (they decide nothing): "
               "pd (exudyn, table1) at 10 ms" in line for line in lines)


def test_a_failure_where_the_limit_lies_leaves_it_missing():
    tested = {1e-3: ("stable", ""), 2e-3: ("failed", "solver failed")}
    limit = Limit(1e-3, 2e-3, "failed", "solver failed")
    lines, missing = stability_summary([result(tested, limit, limit)], Path("stability.md"),
                                       tolerance=0.01)
    assert missing == 1
    assert "1 limit(s) missing" in "\n".join(lines)
    assert "no divergence up to: 1 ms to 1 ms" in "\n".join(lines)


def column(arm, verdict):
    return SimpleNamespace(arm=arm, verdicts={c.key: Verdict(math.nan, verdict) for c in CLAIMS})


def test_claims_are_counted_per_claim_and_arm():
    columns = [column("default", "holds"), column("default", "fails"),
               column("table1", "diverged"), column("table1", "failed")]
    lines, missing = claims_summary(columns, Path("results/paper/claims.md"))
    assert missing == len(CLAIMS)  # the failed column: every claim without a verdict
    assert lines[0].endswith("columns per arm: default 2, table1 2) -> results/paper/claims.md")
    assert lines[1] == f"  {CLAIMS[0].key:<{max(len(c.key) for c in CLAIMS)}}  " \
                       "default: 1 holds, 1 fails; table1: 1 diverged, 1 failed"
    assert len(lines) == 1 + len(CLAIMS) + 1 and "|" not in "".join(lines)


def test_counted_lists_verdicts_in_a_fixed_order():
    assert counted(["fails", "holds", "holds", "odd"]) == "2 holds, 1 fails, 1 odd"
