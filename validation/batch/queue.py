"""One queue for every question: the runs of any number of campaigns and verdicts, each
stored into its own results folder, executed together on one runner.

A *job* is one campaign's runs into one folder (`open_job`: the folder prepared, what it
holds already classified, `classify`).  `run_jobs` gives the runs of every job
to the runner at once — a worker never idles while any job has a run left — and stores
each as it finishes: its worker has put the file in place (`validation.batch.store.writing`),
the row is committed with the others that arrived meanwhile (`committing.Committer`).

A *question* is a generator that yields `Batch` es — the runs it needs next, into its
folder — and is sent back their stored rows, in order; what it returns is its answer.
`answer_all` asks every question's next batch, runs all of them as one set of jobs,
hands each question its rows, and repeats until every question has answered: ``flexarm
verify`` judges all its systems at once this way, so that N workers stay busy until the
last wave instead of the end of each system's.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..run.requirements import signal_names
from ..run.scenario import scenario_to_mapping

from .campaign import Campaign, PlannedRun, campaign_keep, expand
from .executor import Runner, SerialRunner
from .fingerprint import is_fresh
from .store.committing import Committer
from .store.errors import NotARunFile
from .store.index import dictionary_for
from .interrupts import Interrupted
from .limits import expected_work
from .store.memory import MemoryStore
from .progress import progress as progress_counter
from .store.folder import ResultStore, environment
from .store.writing import Destination, StoreTask, landed, leave_token

__all__ = ["Job", "open_job", "run_jobs", "Batch", "answer_all", "CampaignSummary",
           "classify", "run_planned", "run_campaign"]


@dataclass
class CampaignSummary:
    """What a campaign invocation did.  ``skipped`` runs were already stored (by the same
    code, verified); ``stale`` were stored by other code and ``damaged`` had a bad file —
    both rerun; ``failed_before`` failed earlier and were not retried."""

    planned: int = 0
    skipped: int = 0
    ok: int = 0
    diverged: int = 0
    failed: int = 0
    stale: list = field(default_factory=list)
    damaged: dict = field(default_factory=dict)
    failed_before: list = field(default_factory=list)
    unstored: list = field(default_factory=list)  # why a finished run could not be stored
    interrupted: int = 0  # the signal number, 0 if not interrupted

    @property
    def done(self) -> int:
        return self.ok + self.diverged + self.failed

    @property
    def any_failed(self) -> bool:
        return bool(self.failed or self.failed_before or self.unstored)

    def __add__(self, other: "CampaignSummary") -> "CampaignSummary":
        """Two invocations' summaries as one (e.g. the rounds of a stability map)."""
        return CampaignSummary(
            planned=self.planned + other.planned, skipped=self.skipped + other.skipped,
            ok=self.ok + other.ok, diverged=self.diverged + other.diverged,
            failed=self.failed + other.failed, stale=self.stale + other.stale,
            damaged={**self.damaged, **other.damaged},
            failed_before=self.failed_before + other.failed_before,
            unstored=self.unstored + other.unstored,
            interrupted=other.interrupted or self.interrupted)

    def line(self, name: str, out) -> str:
        parts = [f"{name}: {self.planned} runs"]
        if self.skipped:
            parts.append(f"{self.skipped} already stored")
        if self.done or not self.skipped:
            parts.append(f"ran {self.done}: {self.ok} ok, {self.diverged} diverged, "
                         f"{self.failed} failed")
        else:
            parts.append("nothing to run")
        if self.failed_before:
            parts.append(f"{len(self.failed_before)} failed earlier (not retried: "
                         "--retry-failed)")
        if self.stale:
            parts.append(f"{len(self.stale)} made by other code, rerun")
        if self.damaged:
            parts.append(f"{len(self.damaged)} damaged, rerun ({', '.join(self.damaged)})")
        if self.unstored:
            parts.append(f"{len(self.unstored)} NOT STORED ({'; '.join(self.unstored[:3])}"
                         f"{'; ...' if len(self.unstored) > 3 else ''})")
        return "; ".join(parts) + f" -> {out}"


def classify(planned: list[PlannedRun], store: ResultStore, *, retry_failed: bool,
             reuse_stale: bool, rerun: bool = False) -> tuple[list[PlannedRun], CampaignSummary]:
    """Which planned runs to execute, after verifying what ``store`` holds: a run is
    skipped only if its row exists, its file verifies (size and SHA-256), and it was made
    by the same code (or ``reuse_stale``); failed runs are redone with ``retry_failed``;
    with ``rerun`` every run is (``flexarm run``: asked to run, it runs)."""
    summary = CampaignSummary(planned=len(planned))
    if rerun:
        return list(planned), summary
    wanted = {r.run_id for r in planned}
    # Every row is read (not only the wanted ones): a damaged index shows on any page.
    rows = {r.run_id: r for r in store.rows() if r.run_id in wanted}
    for run in planned:  # a file whose row was lost: its metadata rebuilds the row
        path = store.out / "runs" / f"{run.run_id}.npz" if store.out else None
        if run.run_id not in rows and path is not None and path.exists():
            try:
                rows[run.run_id] = store.adopt(path)
            except NotARunFile:
                pass  # unreadable: the run is redone and the file replaced
    damaged = store.verify(list(rows.values()))
    todo = []
    for run in planned:
        row = rows.get(run.run_id)
        if row is None:
            todo.append(run)
        elif run.run_id in damaged:
            summary.damaged[run.run_id] = damaged[run.run_id]
            todo.append(run)
        elif not is_fresh(row) and not reuse_stale:
            summary.stale.append(run.run_id)
            todo.append(run)
        elif row.status == "failed" and retry_failed:
            todo.append(run)
        else:
            summary.skipped += 1
            if row.status == "failed":
                summary.failed_before.append(run.run_id)
    return todo, summary


@dataclass
class Job:
    """One campaign's runs into one results folder: the store, where its workers store
    (``destination``), the runs to execute and the summary of what happened."""

    store: ResultStore
    destination: Destination
    todo: list[PlannedRun]
    summary: CampaignSummary


def open_job(campaign: Campaign, out, planned: list[PlannedRun], *, retry_failed: bool = False,
             reuse_stale: bool = False, rerun: bool = False) -> Job:
    """Prepare ``out`` (a results folder, or a `MemoryStore`) for ``campaign``'s runs
    ``planned`` and find those it does not hold yet (`classify`)."""
    if isinstance(out, MemoryStore):
        todo, summary = classify(planned, out, retry_failed=retry_failed,
                                 reuse_stale=reuse_stale, rerun=rerun)
        return Job(out, Destination(None, campaign.name, environment()), todo, summary)
    store = ResultStore(out)
    store.prepare()
    store.set_campaign(campaign.name, {"description": campaign.description,
                                       "report": campaign.report})
    store.remove_stale_temporaries()
    todo, summary = classify(planned, store, retry_failed=retry_failed,
                             reuse_stale=reuse_stale, rerun=rerun)
    dictionary = b""
    if todo:  # the details of a campaign's runs compressed against its first one
        first = todo[0].scenario
        dictionary = dictionary_for(scenario_to_mapping(first), environment(),
                                    signal_names(first))
        store.add_dictionary(dictionary)
    destination = Destination(str(store.out), campaign.name, environment(),
                              campaign_keep(campaign), leave_token(store.out) if todo else None,
                              dictionary)
    return Job(store, destination, todo, summary)


def run_jobs(jobs: list[Job], runner, *, progress: bool = True, label: str = "") -> None:
    """Execute the runs of every job on ``runner`` at once and store them (module
    docstring); each job's summary counts its runs.  On SIGINT/SIGTERM what finished is
    kept — with the runs whose workers had put their files in place when they were
    stopped — and every summary's ``interrupted`` holds the signal number."""
    jobs = [j for j in jobs if j.todo]
    if not jobs:
        return
    committers = [Committer(j.store) for j in jobs]
    bar = progress_counter(sum(len(j.todo) for j in jobs), label, enabled=progress)

    def idle():
        waits = [w for w in (c.idle() for c in committers) if w is not None]
        return min(waits, default=None)

    tasks = (((k, r.run_id), StoreTask(r.run_id, r.scenario, r.sweep,  # checked: not parsed
                                        {a: _jsonable(v) for a, v in r.axes.items()},  # again
                                        j.destination if r.keep is None else
                                        replace(j.destination, keep=r.keep)))
             for k, j in enumerate(jobs) for r in j.todo)
    results = runner.results(tasks, idle)
    try:
        for key, stored in results:
            job = jobs[key[0]]
            if stored.result is not None:  # an in-memory store: the result itself
                job.store.keep(stored.rid, *stored.result)
            else:
                stored = landed(job.store.out, stored)
            if stored.values is None:
                job.summary.unstored.append(stored.error)  # this run's place only
            else:
                committers[key[0]].add(stored.values)
                _count(job.summary, stored.status)
                bar.set_postfix(**{status: sum(getattr(j.summary, status) for j in jobs)
                                   for status in ("ok", "diverged", "failed")})
            bar.update(1)
    except Interrupted as exc:
        # The runs in flight end first (a signal that landed here, between two results,
        # left them running): no worker puts a file in place after the look below.
        results.close()
        for job, committer in zip(jobs, committers):
            job.summary.interrupted = exc.signum
            committer.flush()
            for row in _landed_uncommitted(job, job.todo):
                _count(job.summary, row.status)
    finally:
        try:
            for committer in committers:  # what finished is stored, whatever stopped us
                committer.flush()
        finally:
            bar.close()
            for job in jobs:
                if job.destination.reach:
                    (job.store.runs_dir / job.destination.reach).unlink(missing_ok=True)


@dataclass
class Batch:
    """The runs a question needs next, stored into ``out`` under the campaign ``name``."""

    out: Path
    name: str
    runs: list[PlannedRun]
    description: str = ""
    summary: CampaignSummary = field(default_factory=CampaignSummary)


def answer_all(questions: list, runner, *, progress: bool = False, label: str = "") -> list:
    """The answers of ``questions`` (generators of `Batch` es, sent the rows of each
    batch's runs in order), their batches run together (module docstring).  Raises
    `Interrupted` on SIGINT/SIGTERM, after storing what finished."""
    answers: list = [None] * len(questions)
    waiting: dict[int, Batch] = {}

    def ask(i: int, rows) -> None:
        try:
            waiting[i] = questions[i].send(rows)
        except StopIteration as done:
            answers[i] = done.value

    for i in range(len(questions)):
        ask(i, None)
    while waiting:
        batches = dict(waiting)
        jobs = {}
        for i, b in batches.items():
            unique = list({r.run_id: r for r in b.runs}.values())
            jobs[i] = open_job(Campaign(name=b.name, base={}, sweeps=(),
                                        description=b.description), b.out, unique)
        run_jobs(list(jobs.values()), runner, progress=progress, label=label)
        for i, b in batches.items():
            b.summary = jobs[i].summary
            if b.summary.interrupted:
                raise Interrupted(b.summary.interrupted)
        for i, b in batches.items():
            store = jobs[i].store
            rows = {r.run_id: r for r in store.rows_of(r.run_id for r in b.runs)}
            store.close()
            del waiting[i]
            ask(i, [rows[r.run_id] for r in b.runs])
    return answers


def run_planned(planned, out: str | Path, *, name: str, description: str = "",
                runner: Runner | None = None, progress: bool = True, label: str | None = None,
                export: bool = True, rerun: bool = False) -> CampaignSummary:
    """Run the runs ``planned`` (`PlannedRun`: made by a verdict — checks, bisections,
    searches — or ``flexarm run``'s one run, not expanded from a campaign file) into
    ``out`` under the campaign ``name``, as `run_campaign` runs a campaign's, the longest
    first (`limits.expected_work`: the last runs to start are short, so the workers of a
    round end together); ``rerun``: all of them, whatever the folder holds."""
    campaign = Campaign(name=name, base={}, sweeps=(), description=description)
    longest_first = sorted(planned, key=lambda r: -expected_work(r.scenario))  # ties: in order
    return run_campaign(campaign, out, runner=runner, progress=progress, only=longest_first,
                        label=label, export=export, rerun=rerun)


def run_campaign(campaign: Campaign, out: str | Path, *, runner: Runner | None = None,
                 retry_failed: bool = False, reuse_stale: bool = False,
                 progress: bool = True, only: list[PlannedRun] | None = None,
                 label: str | None = None, export: bool = True,
                 rerun: bool = False) -> CampaignSummary:
    """Expand ``campaign`` and run what ``out`` does not hold yet (`classify`); every run is
    stored as soon as it finishes.  On SIGINT/SIGTERM, what finished is kept and
    ``summary.interrupted`` holds the signal number.

    Parameters
    ----------
    campaign : Campaign
        What to run (`load_campaign`, `campaign_from_mapping`).
    out : str or pathlib.Path
        The results folder (created if needed).
    runner : Runner, optional
        Where the runs execute (`make_runner`; default: one after the other in this
        process).
    retry_failed : bool
        Run again the runs stored as failed.
    reuse_stale : bool
        Keep runs stored by other code instead of running them again.
    progress : bool
        A progress bar on stderr.
    only : list of PlannedRun, optional
        These of the campaign's runs instead of all (`expand`).
    label : str, optional
        The progress bar's label (default: the campaign's name).
    export : bool
        Write metrics.csv and manifest.json at the end (a search calling this for every
        batch exports once, when it is done).
    rerun : bool
        Run every run again, stored or not.

    Returns
    -------
    CampaignSummary
        What was run, skipped, stored, failed (``line()``: one line to print).

    Examples
    --------
    >>> import tempfile
    >>> from validation import campaign_from_mapping, run_campaign
    >>> campaign = campaign_from_mapping({
    ...     "name": "short", "scenario": {"duration": 0.02, "transient": 0.0},
    ...     "sweep": [{"name": "seeds", "grid": {"seed": [1, 2]}}]})
    >>> summary = run_campaign(campaign, tempfile.mkdtemp(), progress=False)
    >>> summary.planned, summary.ok
    (2, 2)
    """
    planned = only if only is not None else expand(campaign)
    job = open_job(campaign, out, planned, retry_failed=retry_failed, reuse_stale=reuse_stale,
                   rerun=rerun)
    own = runner is None and bool(job.todo)
    runner = runner or SerialRunner()
    try:
        run_jobs([job], runner, progress=progress, label=label or campaign.name)
    finally:
        if own:
            runner.close()
    if export:
        job.store.export()
    job.store.close()
    return job.summary


def _count(summary: CampaignSummary, status: str) -> None:
    setattr(summary, status, getattr(summary, status) + 1)


def _landed_uncommitted(job: Job, runs: list[PlannedRun]) -> list:
    """Adopt the files of ``runs`` that their workers put in place before they were
    stopped, where the index holds no row of them (a result that never came back, or
    whose row the signal stopped from being committed): finished runs, kept."""
    store = job.store
    if job.destination.out is None:  # in memory: nothing was put in place
        return []
    landed_ids = [r.run_id for r in runs if (store.runs_dir / f"{r.run_id}.npz").is_file()]
    known = {row.run_id for row in store.rows_of(landed_ids)}
    adopted = []
    for rid in landed_ids:
        if rid not in known:
            try:
                adopted.append(store.adopt(store.runs_dir / f"{rid}.npz"))
            except NotARunFile:
                pass  # not an intact run file: the run is redone on resume
    return adopted


def _jsonable(value):
    return value.item() if isinstance(value, np.generic) else value


