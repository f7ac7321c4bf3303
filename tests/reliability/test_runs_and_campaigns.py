"""Reliability of runs and campaigns: divergence as a result, crash safety under SIGKILL,
determinism, and solver failures."""
import os
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from campaign_testing import campaign_toml, metrics_table, stored_count
from cli_testing import flexarm
from validation.batch.campaign import campaign_from_mapping
from validation.batch.queue import run_campaign
from validation.batch.executor import SerialRunner
from validation.run.loop import run_scenario
from validation.run.scenario import scenario_from_mapping
from validation.batch.store.folder import ResultStore

UNSTABLE = {"controller": {"kind": "pd", "options": {"kd": [8.0, 500.0]}}}


@pytest.mark.parametrize("plant", ["reduced", "exudyn"])
def test_divergence_is_recorded_when_the_bounds_are_left(plant):
    """Unstable gains end the run as "diverged" at the first sample beyond the bounds."""
    s = scenario_from_mapping({"plant": {"kind": plant}, "duration": 1.0, "transient": 0.5,
                               **UNSTABLE})
    result = run_scenario(s)
    assert result.status == "diverged" and "exceeds" in result.message
    # The same run with bounds too wide to trigger shows when the default ones are left.
    wide = scenario_from_mapping({"plant": {"kind": plant}, "duration": result.end_time + 0.05,
                                  "transient": 0.0,
                                  "divergence": {"max_angle": 1e9, "max_rate": 1e9,
                                                 "max_deflection": 1e9}, **UNSTABLE})
    free = run_scenario(wide)
    b = s.divergence
    defl = np.abs(free.select(["tip_defl1", "tip_defl2"])) / np.array([[0.5], [0.5]])
    beyond = ((np.abs(free.select(["theta1", "theta2"])) > b.max_angle).any(0)
              | (np.abs(free.select(["theta1_dot", "theta2_dot"])) > b.max_rate).any(0)
              | (defl > b.max_deflection).any(0) | ~np.isfinite(free.signals).all(0))
    first = free.time[np.flatnonzero(beyond)[0]] if beyond.any() else free.end_time
    # Stopped exactly at the sample where the state left its bounds (within one sample).
    assert abs(result.end_time - first) <= s.Ts + 1e-12
    assert np.isfinite(result.signals).all()  # nothing after the divergence is recorded


def test_a_diverging_run_does_not_stop_the_campaign(tmp_path):
    spec = {"name": "mixed", "scenario": {"duration": 1.0, "transient": 0.5},
            "sweep": [{"zip": {"name": ["stable", "unstable", "stable-2"],
                               "controller.kind": ["pbc", "pd", "pd"],
                               "controller.options": [{}, {"kd": [8.0, 500.0]},
                                                      {"kd": [8.0, 4.0]}]}}]}
    summary = run_campaign(campaign_from_mapping(spec), tmp_path, progress=False)
    assert (summary.ok, summary.diverged, summary.failed) == (2, 1, 0)
    store = ResultStore(tmp_path)
    rows = store.rows()
    assert {r.name: r.status for r in rows} == {
        "mixed/stable": "ok", "mixed/unstable": "diverged", "mixed/stable-2": "ok"}
    for row in rows:
        result = store.load(row.run_id)
        assert result.status == row.status and result.signals.shape[1] == len(result.time)


def _spec(n_runs: int) -> dict:
    return {"name": "crash", "scenario": {"duration": 2.0, "transient": 1.0,
                                          "sensors": {"encoder_noise": 1e-4}},
            "sweep": [{"grid": {"seed": list(range(n_runs))}}]}


def _spec_with_a_long_last_run(n_runs: int) -> dict:
    """``n_runs`` short runs (~50 ms each), then one 40 s run (~1 s): the campaign cannot
    end while the short runs are being stored, however fast the machine."""
    spec = _spec(n_runs)
    spec["sweep"].append({"name": "long", "grid": {"duration": [40.0]}})
    return spec


# Seed 1 in make test; more random moments (7 s each) in make test-all.
@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow),
                                  pytest.param(3, marks=pytest.mark.slow)])
def test_sigkill_at_random_moments_then_resume(seed, tmp_path):
    n_short = 16
    spec = _spec_with_a_long_last_run(n_short)
    cfg = tmp_path / "crash.toml"
    cfg.write_text(campaign_toml(spec))
    reference = tmp_path / "reference"
    run_campaign(campaign_from_mapping(spec), reference, runner=SerialRunner(), progress=False)
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "validation.cli", "campaign", str(cfg), "--out", str(out),
           "--workers", "1", "--no-progress"]
    rng = random.Random(seed)
    for _ in range(3):  # kill it three times, at a random moment after it has started
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True)
        # The moment: once a random number of the short runs still to do are stored,
        # plus a random part of one run (~50 ms) — inside a run, while a file is
        # written or renamed, or while its row is committed.  The long last run keeps
        # the campaign alive whatever that number is.
        target = rng.randint(stored_count(out), n_short)
        start = time.time()
        while time.time() - start < 300 and stored_count(out) < target and proc.poll() is None:
            time.sleep(0.005)
        time.sleep(rng.uniform(0.0, 0.05))
        assert proc.poll() is None, f"the campaign ended before the kill: {proc.stderr.read()}"
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
        # Written in the order: file (temporary name, then renamed), then its index row in
        # one transaction: whatever the moment of the kill, the index is readable and every
        # row has a complete file that verifies (metrics_table checks both) and loads.
        if (out / "index.sqlite").exists():
            store = ResultStore(out)
            for row in store.rows():
                store.load(row.run_id)  # never a truncated .npz
            store.close()
    final = flexarm(None, *cmd[3:])
    assert final.returncode == 0, final.stderr
    # Same numbers, no duplicate or missing rows.
    assert metrics_table(out) == metrics_table(reference)
    # Every run file is indexed (a file renamed just before a kill is redone and indexed);
    # a temporary a kill interrupted may stay until it is an hour old (it might belong to a
    # live writer) but is hidden and never taken for a result.
    assert ResultStore(out).unindexed_files() == []

    def visible(folder):
        return {p.name for p in folder.iterdir() if not p.name.startswith(".")}

    assert visible(out) <= {"index.sqlite", "index.sqlite-wal", "index.sqlite-shm", "runs",
                            "metrics.csv", "manifest.json"}
    assert visible(out / "runs") == {f"{rid}.npz" for rid in metrics_table(reference)}


def test_two_invocations_are_bit_identical(tmp_path):
    spec = _spec(3)
    cfg = tmp_path / "det.toml"
    cfg.write_text(campaign_toml(spec))
    for name in ("a", "b"):
        subprocess.run([sys.executable, "-m", "validation.cli", "campaign", str(cfg), "--out",
                        str(tmp_path / name), "--workers", "1", "--no-progress"], check=True,
                       capture_output=True)
    assert metrics_table(tmp_path / "a") == metrics_table(tmp_path / "b")
    for rid in metrics_table(tmp_path / "a"):
        a, b = (ResultStore(tmp_path / n).load(rid) for n in ("a", "b"))
        np.testing.assert_array_equal(a.signals, b.signals)


def test_exudyn_solver_failure_is_recorded_and_nothing_stray_is_written(tmp_path):
    # A Newton tolerance below ANCF round-off cannot be met: Exudyn gives up.
    cfg = tmp_path / "health.toml"
    cfg.write_text('name = "health"\n[scenario]\nduration = 0.5\ntransient = 0.25\n'
                   'plant.kind = "exudyn"\n'
                   '[[sweep]]\nzip.name = ["fails", "runs"]\n'
                   'zip.plant.newton_tolerance = [1e-16, 1e-6]\n')
    work = tmp_path / "cwd"
    work.mkdir()
    proc = flexarm(work, "campaign", cfg, "--out", tmp_path / "out", "--workers", "1",
                   "--no-progress")
    assert proc.returncode == 1  # a run failed to execute
    assert "1 ok, 0 diverged, 1 failed" in proc.stdout
    rows = ResultStore(tmp_path / "out").rows()
    failed = [r for r in rows if r.status == "failed"]
    assert len(rows) == 2 and len(failed) == 1 and failed[0].name == "health/fails"
    assert "Exudyn solver failed" in failed[0].message
    assert os.listdir(work) == []  # no solution/ or other Exudyn files in the working dir


def test_a_diverged_run_prints_no_numpy_warnings(tmp_path):
    """Gains of 1e300 overflow the metrics' squares and the float32 store: the run is
    "diverged", its metrics inf or nan, and nothing but the report is printed."""
    done = flexarm(None, "run", "--controller", "pd", "--set",
                   "controller.options.kp=[1e300, 1e300]", "--duration", "1", "--set",
                   "transient=0.5", "--out", tmp_path / "out")
    assert done.returncode == 0, done.stderr
    assert "diverged: " in done.stdout
    assert "Warning" not in done.stderr + done.stdout, done.stderr
    (row,) = ResultStore(tmp_path / "out").rows()
    assert row.status == "diverged"


GARBAGE_FORM = '''
from controllers import JointPD


class Garbage(JointPD):
    """A PD whose compiled form is not one."""

    def __call__(self, t, x, ref):
        return super().__call__(t, x, ref)

    def compiled(self):
        return "a kernel, honest"
'''


def test_a_law_whose_compiled_form_is_garbage_fails_its_run_naming_the_contract(plugin_lab):
    """Known bad (issue 48, 15): "AttributeError: 'str' object has no attribute 'pointer'".
    Now the run fails naming the law and what a compiled form must be."""
    from validation.batch.worker import execute_run
    plugin_lab({"garbagelaws.py": GARBAGE_FORM})
    s = scenario_from_mapping({"duration": 0.01, "controller": {"kind": "garbagelaws:Garbage"}})
    result, _ = execute_run(s)
    assert result.status == "failed"
    assert "garbagelaws:Garbage.compiled() returned 'a kernel, honest'" in result.message
    assert "controllers.CompiledLaw" in result.message and "pointer" not in result.message
