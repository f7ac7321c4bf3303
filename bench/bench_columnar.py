"""Which columnar form for the metrics of many runs (issue 46): typed SQLite columns or
Apache Parquet files queried by DuckDB, measured on the same rows.

    python bench/bench_columnar.py [ROWS ...]        (default: 10000 100000)

Rows like a metrics-only campaign's: 140 metrics (100 varying floats, 20 zeros, 17 NaN,
3 short strings) and the identity columns, arriving as the store receives them — in
batches of 512 rows (`validation.batch.store.committing.MAX_ROWS`), each committed at once.
SQLite: one table, a ``REAL`` column per metric, one transaction per batch (what
`validation.batch.store.index.insert_rows` does).  Parquet: one file per batch (a file cannot
be appended to; several writer processes each write their own), read back by DuckDB over
``*.parquet``; and the same after compacting them into one file.  Measured: writing,
reading every metric of every row into numpy, a query (one metric above its 99th
percentile), bytes per row.  Needs ``duckdb`` and ``pyarrow`` for the Parquet columns
(not dependencies of the project: install them beside it to run this).  Prints the
table, writes bench/results/columnar.json.
"""
from __future__ import annotations

import shutil
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _report import report

BATCH = 512
METRICS = 140


def table(rows: int, seed: int = 0) -> tuple[list[str], np.ndarray, list[str]]:
    """(metric names, float values (rows, 137) with zeros and NaN, run ids)."""
    rng = np.random.default_rng(seed)
    values = rng.lognormal(-3, 1, (rows, METRICS - 3))
    values[:, 100:120] = 0.0
    values[:, 120:] = np.nan
    names = [f"m{j}" for j in range(METRICS - 3)] + ["s1", "s2", "status"]
    return names, values, [f"{i:012x}" for i in range(rows)]


def row_tuples(names, values, ids) -> list[tuple]:
    """The rows as workers hand them to the store: a tuple each (NaN as None)."""
    return [(ids[i], "many/seeds", "ok", *[None if v != v else v for v in values[i]],
             "theta1 theta2", "", "ok") for i in range(len(ids))]


def sqlite_case(folder: Path, names, values, ids, tuples) -> dict:
    path = folder / "index.sqlite"
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("PRAGMA journal_mode=WAL")
    columns = ", ".join(f'"m:{n}" REAL' for n in names)
    db.execute(f"CREATE TABLE runs (run_id TEXT PRIMARY KEY, name TEXT, status TEXT, {columns})")
    sql = (f"INSERT INTO runs VALUES (?, ?, ?, {', '.join('?' * len(names))})")
    t0 = time.perf_counter()
    for start in range(0, len(ids), BATCH):
        db.execute("BEGIN IMMEDIATE")
        db.executemany(sql, tuples[start:start + BATCH])
        db.execute("COMMIT")
    write = time.perf_counter() - t0
    t0 = time.perf_counter()
    selected = ", ".join(f'"m:{n}"' for n in names[:-3])
    got = np.array(db.execute(f"SELECT {selected} FROM runs").fetchall(), dtype=float)
    read = time.perf_counter() - t0
    bound = float(np.nanquantile(values[:, 0], 0.99))
    t0 = time.perf_counter()
    found = db.execute('SELECT run_id FROM runs WHERE "m:m0" > ?', (bound,)).fetchall()
    query = time.perf_counter() - t0
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    db.close()
    assert got.shape == values.shape
    return {"write_s": write, "read_all_s": read, "query_s": query, "found": len(found),
            "bytes_per_row": sum(p.stat().st_size for p in folder.iterdir()) / len(ids)}


def parquet_case(folder: Path, names, values, ids, tuples, compact: bool) -> dict:
    import duckdb
    import pyarrow as pa
    import pyarrow.parquet as pq
    t0 = time.perf_counter()
    for k, start in enumerate(range(0, len(ids), BATCH)):
        batch = tuples[start:start + BATCH]  # the rows, turned into columns
        columns = ["run_id", "name", "status", *(f"m:{n}" for n in names)]
        arrays = {c: pa.array([t[j] for t in batch], type=None if j < 3 or
                              j >= len(columns) - 3 else pa.float64())
                  for j, c in enumerate(columns)}
        pq.write_table(pa.table(arrays), folder / f"part-{k:06d}.parquet")
    if compact:
        merged = pq.read_table(folder)
        for p in folder.glob("part-*.parquet"):
            p.unlink()
        pq.write_table(merged, folder / "metrics.parquet")
    write = time.perf_counter() - t0
    con = duckdb.connect()
    glob = str(folder / "*.parquet")
    t0 = time.perf_counter()
    selected = ", ".join(f'"m:{n}"' for n in names[:-3])
    got = con.execute(f"SELECT {selected} FROM read_parquet('{glob}')").fetchnumpy()
    read = time.perf_counter() - t0
    bound = float(np.nanquantile(values[:, 0], 0.99))
    t0 = time.perf_counter()
    found = con.execute(f"SELECT run_id FROM read_parquet('{glob}') WHERE \"m:m0\" > ?",
                        [bound]).fetchall()
    query = time.perf_counter() - t0
    assert len(got) == len(names) - 3
    return {"write_s": write, "read_all_s": read, "query_s": query, "found": len(found),
            "bytes_per_row": sum(p.stat().st_size for p in folder.iterdir()) / len(ids)}


def main(counts: list[int]) -> None:
    rows = []
    try:
        import duckdb  # noqa: F401
        import pyarrow  # noqa: F401
        parquet = True
    except ImportError:
        parquet = False
    for n in counts:
        names, values, ids = table(n)
        tuples = row_tuples(names, values, ids)
        cases = [("SQLite typed columns", lambda f: sqlite_case(f, names, values, ids, tuples))]
        if parquet:
            cases += [("Parquet per batch + DuckDB",
                       lambda f: parquet_case(f, names, values, ids, tuples, compact=False)),
                      ("Parquet compacted + DuckDB",
                       lambda f: parquet_case(f, names, values, ids, tuples, compact=True))]
        for label, case in cases:
            folder = Path(tempfile.mkdtemp(prefix="flexarm-columnar-"))
            try:
                rows.append({"form": label, "rows": n, **case(folder)})
            finally:
                shutil.rmtree(folder)
    if not parquet:
        print("duckdb or pyarrow not installed: Parquet not measured")
    report("columnar", rows, title="metrics of many runs: typed SQLite columns against "
                                   "Parquet + DuckDB",
           columns=["form", "rows", "write_s", "read_all_s", "query_s", "found",
                    "bytes_per_row"])


if __name__ == "__main__":
    main([int(n) for n in sys.argv[1:]] or [10_000, 100_000])
