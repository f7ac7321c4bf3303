"""What the shipped campaign files' comments say about where a loop holds or diverges agrees
with the runs those campaigns make (as tests/test_readme.py keeps the README's lines
true): each such sentence is listed in `CLAIMS` with the runs that decide it, which are
run here, and no sentence of that kind in ``campaigns/`` goes unlisted.

A claim is judged as the stability map judges a run (`validation.verdicts.stability`):
the campaign's own runs that it names, cut to the map's `stability.DURATION` (2 s, the
second half measured), "diverges" where `stability.outcome` says diverged.  Tracking is
not the question: the reduced plant's PBC + SMO at Ts = 0.2 ms from rest is still in its
start-up transient at 1 s and reads "lost tracking" there, and holds over the campaign's
20 s.  A refined claim runs the plant ``level`` times refined (mesh and step together,
as the map and the mesh check refine it).
"""
import re
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import pytest

from validation.batch.campaign import expand, load_campaign
from validation.run.loop import run_scenario
from validation.run.metrics import all_metrics
from validation.run.plants import plant_settings
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping
from validation.run.tomlfiles import get_dotted
from validation.verdicts import stability

CAMPAIGNS = Path(__file__).resolve().parent.parent / "campaigns"


@dataclass(frozen=True)
class Claim:
    """Runs of ``campaign`` whose fields equal ``where`` (dotted keys of a resolved
    scenario), on the plant refined ``level`` times: every one diverges, or none does."""

    campaign: str
    where: dict
    diverges: bool
    level: int = 0


def _table1(Ts, plant, **more) -> dict:
    return {"arm": "table1", "Ts": Ts, "plant.kind": plant, **more}


_SMO = {"controller.kind": "pbc", "observer.kind": "smo-paper"}
_FAST_REDUCED = Claim("paper.toml", _table1(2e-4, "reduced", **_SMO), diverges=False)

#: (file, words in it) -> the runs that make them true.
CLAIMS = {
    ("paper.toml", "At Ts = 1 ms Table 1's PBC diverges on both plants, with every observer"):
        [Claim("paper.toml", _table1(1e-3, plant, **{"controller.kind": "pbc"}), diverges=True)
         for plant in ("reduced", "exudyn")],
    ("paper.toml", "at Ts = 0.2 ms, where it holds on the reduced plant"): [_FAST_REDUCED],
    ("paper.toml", "the truth plant diverges there too: from rest on the campaign's mesh, "
                   "and moving with the reference once its mesh and step are refined"):
        [Claim("paper.toml", _table1(2e-4, "exudyn", initial_state="rest", **_SMO),
               diverges=True),
         Claim("paper.toml", _table1(2e-4, "exudyn", initial_state="reference", **_SMO),
               diverges=True, level=1)],
    ("stator.toml", "Ts = 0.2 ms (where Table 1's PBC + SMO holds on the reduced plant, as "
                    "in paper.toml)"): [_FAST_REDUCED],
}

#: A sentence that says where a loop holds or diverges: a control period and a verdict.
_VERDICT = re.compile(r"\b(stable|unstable|holds?|diverg\w*)\b", re.I)
_PERIOD = re.compile(r"\bTs\s*=", re.I)


def comment_sentences(path: Path) -> list[str]:
    """The sentences of a TOML file's comment blocks (whole-line comments, joined)."""
    blocks, block = [], []
    for line in path.read_text().splitlines() + [""]:
        if line.lstrip().startswith("#"):
            block.append(line.lstrip()[1:].strip())
        elif block:
            blocks.append(" ".join(block))
            block = []
    return [s for b in blocks for s in re.split(r"\.\s+", b)]


def test_every_comment_on_where_a_loop_holds_is_checked():
    """Every comment sentence of campaigns/ with a control period and a verdict holds a
    listed claim, and every listed claim is in its file (the list cannot go stale)."""
    for path in sorted(CAMPAIGNS.glob("*.toml")):
        for sentence in comment_sentences(path):
            if _VERDICT.search(sentence) and _PERIOD.search(sentence):
                assert any(f == path.name and words in sentence for f, words in CLAIMS), \
                    f"{path.name}: unchecked claim: {sentence!r}"
    for file, words in CLAIMS:
        text = " ".join(comment_sentences(CAMPAIGNS / file))
        assert words in text, (file, words)


def test_the_unchecked_claim_of_the_old_comment_is_caught(tmp_path):
    """Known-bad: a comment that says Table 1 is stable at 0.2 ms on both plants is a
    sentence the check above would have to list (and `_claim_holds` with the truth
    plant's runs refutes it: test_claim_agrees_with_the_runs)."""
    path = tmp_path / "paper.toml"
    path.write_text("# Table 1 diverges at Ts = 1 ms (see the stability map): its system "
                    "also runs at\n# Ts = 0.2 ms, where the sampled loop is stable, on both "
                    "plants.\nname = \"paper\"\n")
    sentences = [s for s in comment_sentences(path)
                 if _VERDICT.search(s) and _PERIOD.search(s)]
    assert sentences and not any(words in s for s in sentences for _, words in CLAIMS)


def _outcome(data: dict, level: int) -> str:
    data = dict(data, duration=stability.DURATION, transient=stability.DURATION / 2)
    if level:
        data["plant"] = plant_settings(data["plant"]).refined(level)
    result = run_scenario(scenario_from_mapping(data))
    row = SimpleNamespace(status=result.status, message=result.message,
                          metrics=all_metrics(result) if result.status == "ok" else {})
    return stability.outcome(row)[0]


def _runs(claim: Claim) -> list[dict]:
    runs = [scenario_to_mapping(r.scenario)
            for r in expand(load_campaign(CAMPAIGNS / claim.campaign))]
    return [d for d in runs if all(get_dotted(d, k) == v for k, v in claim.where.items())]


def _claim_holds(claim: Claim) -> tuple[bool, list]:
    """Whether every run the claim names diverges (or none does), with the outcomes."""
    runs = _runs(claim)
    assert runs, f"{claim.campaign} has no run with {claim.where}"
    outcomes = [(d["name"], d["initial_state"], _outcome(d, claim.level)) for d in runs]
    assert not any(o == "failed" for *_, o in outcomes), outcomes  # no verdict at all
    return all((o == "diverged") == claim.diverges for *_, o in outcomes), outcomes


@pytest.mark.parametrize("key", list(CLAIMS), ids=lambda k: f"{k[0]}: {k[1][:40]}")
def test_claim_agrees_with_the_runs(key):
    for claim in CLAIMS[key]:
        holds, outcomes = _claim_holds(claim)
        assert holds, (key, claim, outcomes)


def test_stable_on_both_plants_at_0_2_ms_is_refuted():
    """Known-bad: the old comment's "stable at Ts = 0.2 ms, on both plants" fails on the
    truth plant's runs (from rest: diverged within a millisecond)."""
    holds, outcomes = _claim_holds(Claim("paper.toml", _table1(2e-4, "exudyn", **_SMO),
                                         diverges=False))
    assert not holds, outcomes
