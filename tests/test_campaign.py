"""Campaigns: configuration errors, sweep expansion, run ids, resume after a kill,
identical results on every executor, and reports."""
import dataclasses
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from campaign_testing import campaign_toml, metrics_table
from validation._config import ConfigError
from validation.campaign import (SerialExecutor, campaign_from_mapping, expand, load_campaign,
                                 make_executor, run_campaign)
from validation.claims import write_claims
from validation.report import SECTIONS, write_report
from validation.scenario import scenario_from_mapping, scenario_to_mapping
from validation.store import ResultStore, run_id

ROOT = Path(__file__).resolve().parent.parent
SMALL = {"name": "small", "scenario": {"duration": 0.3, "sensors": {"encoder_noise": 1e-4}},
         "sweep": [{"name": "payload", "grid": {"true_params": {"Mp": [0.0, 0.5]},
                                                "seed": [1, 2]}},
                   {"name": "observer", "zip": {"observer.kind": ["smo-bl", "smo-pos"],
                                                "name": ["bl", "pos"]}}]}


# --- configuration ------------------------------------------------------------------------
@pytest.mark.parametrize("data, path", [
    ({"sweeps": []}, "sweeps"),
    ({"sweep": [{"grid": {"plant.kind": ["reduced"]}, "grd": {}}]}, "sweep[0].grd"),
    ({"sweep": [{"grid": {"plant.kind": []}}]}, "sweep[0].grid.plant.kind"),
    ({"sweep": [{"grid": {"plant.kind": "reduced"}}]}, "sweep[0].grid.plant.kind"),
    ({"sweep": [{"grid": {"plant.kind": ["fem"]}}]}, "plant.kind"),
    ({"sweep": [{"grid": {"true_params.EI1": [-1.0]}}]}, "true_params.EI1"),
    ({"sweep": [{"grid": {"true_params.Mp": ["heavy"]}}]}, "true_params.Mp"),
    ({"sweep": [{"zip": {"seed": [1, 2], "name": ["a"]}}]}, "sweep[0].zip"),
    ({"sweep": [{"grid": {"plant.kind": {"scale": [2.0]}}}]}, "sweep[0].grid.plant.kind"),
    # An unknown spec name reads as one more key level: the error names that key.
    ({"sweep": [{"random": {"samples": 3, "true_params.Mp": {"normal": [0, 1]}}}]},
     "sweep[0].random.true_params.Mp.normal"),
    ({"sweep": [{"random": {"samples": 0, "true_params.Mp": {"uniform": [0, 1]}}}]},
     "sweep[0].random.samples"),
    ({"sweep": [{"random": {"samples": 2, "true_params.Mp": {"uniform": [1, 0]}}}]},
     "sweep[0].random.true_params.Mp"),
    ({"scenario": {"duration": -1.0}}, "scenario.duration"),
    ({"sweep": [{"grid": {"nonsense.key": [1]}}]}, "nonsense"),
])
def test_config_errors_name_the_key(data, path):
    with pytest.raises(ConfigError) as exc:
        expand(campaign_from_mapping({"name": "bad", **data}))
    assert exc.value.path == path, str(exc.value)


def test_include_files_and_their_errors(tmp_path):
    (tmp_path / "base.toml").write_text("[scenario]\nduration = 0.5\nseed = 3\n")
    (tmp_path / "c.toml").write_text('include = "base.toml"\nname = "c"\n[scenario]\nseed = 4\n')
    campaign = load_campaign(tmp_path / "c.toml")
    (run,) = expand(campaign)
    assert run.scenario.duration == 0.5 and run.scenario.seed == 4  # the includer overrides
    (tmp_path / "loop.toml").write_text('include = "loop.toml"\n')
    with pytest.raises(ConfigError, match="includes itself"):
        load_campaign(tmp_path / "loop.toml")
    (tmp_path / "missing.toml").write_text('include = "nowhere.toml"\n')
    with pytest.raises(ConfigError, match="cannot read"):
        load_campaign(tmp_path / "missing.toml")
    (tmp_path / "broken.toml").write_text("name = = 1\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_campaign(tmp_path / "broken.toml")


# --- expansion -------------------------------------------------------------------------------
def test_sweep_expansion():
    c = campaign_from_mapping({"name": "x", "scenario": {"true_params": {"EI1": 10.0}}, "sweep": [
        {"name": "g", "grid": {"plant": {"kind": ["reduced", "exudyn"]},
                               "true_params.EI1": {"scale": [0.7, 1.3]}},
         "zip": {"controller.kind": ["pbc", "pd", "ct"], "seed": [1, 2, 3]}},
        {"name": "r", "random": {"samples": 4, "seed": 9,
                                 "true_params": {"Mp": {"uniform": [0.0, 1.0]}},
                                 "sensors.encoder_noise": {"loguniform": [1e-5, 1e-3]},
                                 "observer.kind": {"choices": ["smo-bl", "smo-pos"]}}},
    ]})
    runs = expand(c)
    grid = [r for r in runs if r.sweep == "g"]
    assert len(grid) == 2 * 2 * 3  # grid product × zip pairs
    assert {r.axes["true_params.EI1"] for r in grid} == {7.0, 13.0}
    assert {(r.axes["controller.kind"], r.axes["seed"]) for r in grid} == {
        ("pbc", 1), ("pd", 2), ("ct", 3)}
    rnd = [r for r in runs if r.sweep == "r"]
    assert len(rnd) == 4
    assert all(0 <= r.axes["true_params.Mp"] <= 1 for r in rnd)
    assert all(1e-5 <= r.axes["sensors.encoder_noise"] <= 1e-3 for r in rnd)
    again = expand(c)  # seeded: the same draws and ids every time
    assert [r.run_id for r in again] == [r.run_id for r in runs]
    assert all(r.scenario.name == f"x/{r.sweep}" for r in runs)


def test_duplicate_runs_are_kept_once():
    # The same resolved scenario (names included) reached from two sweeps is one run.
    c = campaign_from_mapping({"name": "d", "sweep": [{"grid": {"seed": [0], "name": ["x"]}},
                                                     {"grid": {"seed": [0, 1], "name": ["x"]}}]})
    assert len(expand(c)) == 2


def test_run_id_is_a_function_of_the_resolved_scenario():
    a = scenario_to_mapping(scenario_from_mapping({"true_params": {"Mp": 0.5}, "seed": 1}))
    b = scenario_to_mapping(scenario_from_mapping({"seed": 1, "true_params": {"Mp": 0.5}}))
    c = scenario_to_mapping(scenario_from_mapping({"seed": 2, "true_params": {"Mp": 0.5}}))
    shuffled = json.loads(json.dumps(a, sort_keys=False))
    shuffled = dict(reversed(list(shuffled.items())))
    assert run_id(a) == run_id(b) == run_id(shuffled) != run_id(c)
    assert len(run_id(a)) == 12
    # Written explicitly with the default value, a key does not change the id.
    d = scenario_to_mapping(scenario_from_mapping({"seed": 1, "true_params": {"Mp": 0.5},
                                                   "Ts": 1e-3}))
    assert run_id(d) == run_id(a)


# --- execution -----------------------------------------------------------------------------------
def test_executors_give_identical_metrics(tmp_path):
    c = campaign_from_mapping(SMALL)
    results = {}
    serial, close = make_executor("local", 1)
    run_campaign(c, tmp_path / "serial", executor=serial, progress=False)
    close()
    results["serial"] = metrics_table(tmp_path / "serial")
    pool, close = make_executor("local", 2)
    try:
        run_campaign(c, tmp_path / "pool", executor=pool, progress=False)
    finally:
        close()
    results["pool"] = metrics_table(tmp_path / "pool")
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, host="127.0.0.1") as cluster:
        executor, close = make_executor("dask", scheduler=cluster.scheduler_address)
        try:
            run_campaign(c, tmp_path / "dask", executor=executor, progress=False)
        finally:
            close()
    results["dask"] = metrics_table(tmp_path / "dask")
    assert len(results["serial"]) == 6
    # Same seeds, same arithmetic: bit-identical metrics (wall time excluded).
    assert results["serial"] == results["pool"] == results["dask"]


def test_resume_after_a_kill(tmp_path):
    # 20 runs of ~50 ms: killed after the 3rd result, 17 runs remain to land the kill in.
    spec = {"name": "resume", "scenario": {"duration": 2.0},
            "sweep": [{"grid": {"seed": list(range(20)),
                                "sensors.encoder_noise": [1e-4]}}]}
    cfg = tmp_path / "resume.toml"
    cfg.write_text(campaign_toml(spec))
    reference = tmp_path / "reference"
    run_campaign(campaign_from_mapping(spec), reference, executor=SerialExecutor(),
                 progress=False)
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "validation.cli", "campaign", str(cfg), "--out", str(out),
           "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and len(ResultStore(out).completed()) < 3:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    partial = ResultStore(out).completed()
    assert 3 <= len(partial) < 20, "the kill must land mid-campaign"
    json.loads((out / "manifest.json").read_text())  # always valid JSON
    summary = subprocess.run(cmd, capture_output=True, text=True)
    assert summary.returncode == 0, summary.stderr
    assert f"{len(partial)} already done" in summary.stdout
    assert metrics_table(out) == metrics_table(reference)  # no duplicates, same numbers
    again = subprocess.run(cmd, capture_output=True, text=True)
    assert "20 already done" in again.stdout


def test_failed_runs_are_redone_only_on_request(tmp_path):
    c = campaign_from_mapping({"name": "f", "scenario": {"duration": 0.2}})
    (run,) = expand(c)
    store = ResultStore(tmp_path)
    from validation.results import RunResult
    store.add(run.run_id, RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0)),
                                    status="failed", message="boom",
                                    config=scenario_to_mapping(run.scenario)),
              {"status": "failed"})
    assert run_campaign(c, tmp_path, progress=False).skipped == 1
    summary = run_campaign(c, tmp_path, progress=False, retry_failed=True)
    assert summary.ok == 1 and store.completed()[run.run_id] == "ok"
    assert len(store.metrics()) == 1


# --- reports ------------------------------------------------------------------------------------------
def test_report_from_stored_results(tmp_path):
    spec = {"name": "rep", "scenario": {"duration": 2.5, "observer": {"kind": "smo-paper"}},
            "report": {"figures": ["rep/both"]},
            "sweep": [{"name": "both", "grid": {"plant.kind": ["reduced", "exudyn"]}},
                      {"name": "payload", "grid": {"true_params.Mp": [0.0, 0.3]}}]}
    run_campaign(campaign_from_mapping(spec), tmp_path, progress=False)
    html_path, md_path = write_report(tmp_path)
    md, page = md_path.read_text(), html_path.read_text()
    for section in SECTIONS:
        assert f"## {section}" in md and f"<h2>{section}</h2>" in page
    assert "Fig. 3" in md and "Fig. 7" in md and "metrics vs true_params.Mp" in md
    assert page.count("data:image/png;base64,") >= 7 and "http" not in page.split("<body>")[1]
    assert (tmp_path / "report" / "arm.gif").stat().st_size > 10_000


def test_claims_table_of_the_paper_campaign(tmp_path):
    c = load_campaign(ROOT / "campaigns" / "paper.toml")
    runs = [r for r in expand(c) if r.scenario.name in ("paper/pbc+smo-paper",
                                                         "paper/pbc+smo-paper+disturbance")]
    assert len(runs) == 4  # both plants, with and without the disturbance
    short = [dataclasses.replace(r, scenario=dataclasses.replace(r.scenario, duration=11.0))
             for r in runs]  # past the disturbance at 10 s; ids stay those of the campaign
    run_campaign(c, tmp_path, progress=False, only=short)
    table = write_claims(tmp_path)
    assert table.count("\n") == 9  # header, rule, 8 claims
    assert "holds" in table and "not run" not in table
    assert (tmp_path / "claims.csv").exists()


def test_shipped_campaigns_expand():
    counts = {name: len(expand(load_campaign(ROOT / "campaigns" / f"{name}.toml")))
              for name in ("paper", "mismatch", "robustness")}
    assert counts == {"paper": 15, "mismatch": 29, "robustness": 26}


def test_readme_campaign_example_is_valid(tmp_path):
    """The complete example in the README parses, checks and expands."""
    readme = (ROOT / "README.md").read_text()
    block = readme.split("```toml\n# my.toml")[1].split("```")[0]
    text = "# my.toml" + block.replace('include = "campaigns/base.toml"',
                                       f'include = "{ROOT / "campaigns" / "base.toml"}"')
    (tmp_path / "my.toml").write_text(text)
    runs = expand(load_campaign(tmp_path / "my.toml"))
    assert len(runs) == 2 * 4 * 3 * 2 + 8
    assert {r.scenario.plant.kind for r in runs} == {"reduced", "exudyn"}
    assert runs[0].scenario.disturbances[0].kind == "pulse"


def test_metrics_table_keeps_identifiers_as_text(tmp_path):
    from validation.results import RunResult
    store = ResultStore(tmp_path)
    empty = RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0)), status="ok",
                      config={"name": "1e5"})
    for rid in ("1234567e8901", "000000000042", "abcdefabcdef"):
        store.add(rid, empty, {"status": "ok", "track_max_1": 0.5})
    rows = store.metrics()
    assert sorted(r["run_id"] for r in rows) == ["000000000042", "1234567e8901", "abcdefabcdef"]
    assert all(r["name"] == "1e5" and r["track_max_1"] == 0.5 for r in rows)
