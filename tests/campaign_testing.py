"""Helpers shared by the campaign tests (tests/test_campaign.py, tests/reliability/)."""
import json
import math
import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from validation.batch.store.folder import ResultStore, StoreError




def metrics_table(out) -> dict:
    """The index of a results folder as {run id: {field: value}} — name, status, message,
    end time and every metric (wall-clock times are timings, not metrics), not the code
    fingerprint (this process caches its own, a
    subprocess computes it afresh).  NaN (a metric that does not apply) becomes the string
    "nan" so that equal tables compare equal.  Asserts there are no duplicate rows and
    that every run file verifies."""
    store = ResultStore(out)
    try:
        rows = store.rows()
        assert store.verify(rows) == {}, "damaged run files"
    finally:
        store.close()
    ids = [r.run_id for r in rows]
    assert len(ids) == len(set(ids)), "duplicate rows in the index"
    clean = lambda v: "nan" if isinstance(v, float) and math.isnan(v) else v  # noqa: E731
    table = {}
    for r in rows:
        entry = {"name": r.name, "status": r.status, "message": r.message,
                 "end_time": r.end_time}
        entry |= {k: clean(v) for k, v in r.metrics.items()}
        table[r.run_id] = entry
    return table


def stored_count(out) -> int:
    """How many runs the index of ``out`` holds (0 while there is no index yet); opens
    and closes its own connection, so it can poll a folder another process writes."""
    store = ResultStore(out)
    try:
        return len(store.rows()) if store.exists() else 0
    except StoreError:
        return 0
    finally:
        store.close()


def campaign_toml(spec: dict) -> str:
    """TOML text of a campaign mapping (scalars, lists, one level of tables, [[sweep]]s
    whose axis tables are written with quoted dotted keys)."""
    def value(v):
        return json.dumps(v)

    lines, tables = [], []
    for key, v in spec.items():
        if isinstance(v, dict):
            tables.append((f"[{key}]", v))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            tables += [(f"[[{key}]]", t) for t in v]
        else:
            lines.append(f"{key} = {value(v)}")
    for header, table in tables:
        lines += ["", header]
        for key, v in table.items():
            if isinstance(v, dict):
                lines += [f"{key}.{json.dumps(sub)} = {value(x)}" for sub, x in v.items()]
            else:
                lines.append(f"{key} = {value(v)}")
    return "\n".join(lines) + "\n"


def wait_gone(session: int, timeout: float = 10.0) -> bool:
    """Whether every process of session ``session`` (a command started in its own
    session, every worker it forked — each leads its own process group — and whatever
    they started) has ended within ``timeout`` seconds."""
    import subprocess
    import time
    deadline = time.time() + timeout
    while time.time() < deadline:
        if not subprocess.run(["pgrep", "-s", str(session)], capture_output=True).stdout:
            return True
        time.sleep(0.05)
    return False


@contextmanager
def dask_cluster(folder: Path, workers: int, *, timeout: float = 120.0):
    """A real Dask cluster on localhost, as a user starts one: ``dask scheduler`` and
    ``dask worker --nworkers N --nthreads 1`` processes (this interpreter's), their
    connection file in ``folder``; yields the scheduler's address, ends both after."""
    dask = [str(Path(sys.executable).with_name("dask"))]
    info = folder / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    common = ["--no-dashboard", "--host", "127.0.0.1"]
    scheduler = subprocess.Popen([*dask, "scheduler", "--port", "0", "--scheduler-file",
                                  str(info), *common], env=env, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
    procs = [scheduler]
    try:
        deadline = time.time() + timeout
        while not info.exists() and time.time() < deadline:
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        procs.append(subprocess.Popen(
            [*dask, "worker", "--scheduler-file", str(info), "--nworkers", str(workers),
             "--nthreads", "1", *common], env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True))
        from distributed import Client
        with Client(address, timeout=f"{timeout}s") as client:  # the workers are up
            client.wait_for_workers(workers, timeout=timeout)
        yield address
    finally:
        for proc in reversed(procs):
            try:
                os.killpg(proc.pid, 15)
            except ProcessLookupError:
                pass
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                proc.wait()
