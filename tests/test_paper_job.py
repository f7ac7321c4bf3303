"""The paper reproduction spends runs where they decide something (issue 46, 1): what
each run keeps, which runs the stability map explains, and a claim's own signals read
from a file that keeps them instead of re-simulating the run."""
from pathlib import Path
from types import SimpleNamespace

from validation.batch import worker
from validation.batch.campaign import expand, load_campaign
from validation.batch.store.resimulate import every_signal
from validation.batch.store.runfiles import KEEP_NONE, Keep
from validation.batch.store.folder import ResultStore
from validation.cli import main
from validation.cli.campaigns import paper_keep
from validation.run.scenario import scenario_from_mapping, scenario_to_mapping
from validation.verdicts.claims import CLAIM_RUNS, DISTURBED, SYSTEM
from validation.verdicts.mesh import CHECK_KEEP
from validation.verdicts.claims import beyond_every_limit
from validation.verdicts.stability import cases_from_scenarios

ROOT = Path(__file__).resolve().parent.parent


def test_the_paper_runs_keep_what_their_verdicts_and_figures_read():
    """Every signal of the paper's system (the window family and the figures read them),
    the disturbance claim's four signals of the disturbed run, the metrics of the rest."""
    campaign = load_campaign(ROOT / "campaigns" / "paper.toml")
    kept = {}
    for r in paper_keep(expand(campaign), campaign):
        kept.setdefault(r.scenario.name.split("/")[-1], set()).add(r.keep)
    assert kept[SYSTEM] == {Keep(compress=True)}
    assert kept[DISTURBED] == {CHECK_KEEP}
    assert set(CHECK_KEEP.signals) == {"theta1", "theta2", "theta1_ref", "theta2_ref"}
    assert CLAIM_RUNS == {SYSTEM, DISTURBED}
    others = set().union(*(k for name, k in kept.items() if name not in CLAIM_RUNS))
    assert others == {KEEP_NONE} and len(kept) > 3


def _case_and_row(Ts: float, status: str):
    scenario = scenario_from_mapping({"controller": {"kind": "pd"}, "Ts": Ts})
    (case,) = cases_from_scenarios([scenario])
    row = SimpleNamespace(run_id=f"{status}@{Ts}", status=status,
                          config=scenario_to_mapping(scenario))
    return case, row


def test_a_divergence_beyond_every_level_of_the_map_is_explained():
    """A run that diverged at or beyond its case's first divergence on every level needs
    no mesh check (known-good); one that diverged below it, or one that completed, does
    (known-bad: the map does not explain them); nor does a case whose map found no
    divergence explain anything."""
    case, at_limit = _case_and_row(4e-3, "diverged")
    _, below = _case_and_row(2e-3, "diverged")
    _, completed = _case_and_row(8e-3, "ok")
    _, beyond = _case_and_row(8e-3, "diverged")
    result = SimpleNamespace(case=case, resolved={"divergence": SimpleNamespace(
        levels=[("ANCF 4", 3.0e-3, 3.5e-3), ("ANCF 8", 3.5e-3, 4.0e-3)])})
    rows = [at_limit, below, completed, beyond]
    assert beyond_every_limit([result], rows) == {at_limit.run_id, beyond.run_id}
    unbounded = SimpleNamespace(case=case, resolved={"divergence": SimpleNamespace(
        levels=[("ANCF 4", 1e-2, float("nan"))])})
    assert beyond_every_limit([unbounded], rows) == set()


def test_a_claims_own_signals_are_read_from_a_file_that_keeps_them(tmp_path, monkeypatch):
    """Known-good: a file keeping θ and θd at every sample gives them without a
    re-simulation; known-bad: asking for a signal it does not keep re-simulates."""
    (tmp_path / "c.toml").write_text(
        'name = "c"\n[scenario]\nduration = 0.1\ntransient = 0.05\n'
        '[keep]\nsignals = ["theta1", "theta2", "theta1_ref", "theta2_ref"]\n')
    assert main(["campaign", str(tmp_path / "c.toml"), "--out", str(tmp_path / "o"),
                 "--workers", "1", "--no-progress"]) == 0
    store = ResultStore(tmp_path / "o")
    (row,) = store.rows()
    simulated, original = [], worker.execute_run

    def counting(config):
        simulated.append(config)
        return original(config)
    monkeypatch.setattr(worker, "execute_run", counting)
    names = ("theta1", "theta1_ref")
    result = every_signal(store, row, names)
    assert not simulated and set(names) <= set(result.names)
    assert len(result.names) == 4  # what the file keeps, as it keeps it
    full = every_signal(store, row, ("theta1", "q11"))
    assert len(simulated) == 1 and "q11" in full.names
