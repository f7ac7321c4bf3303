"""A store sized by what you keep (issue 35): bytes per stored run for each choice of a
campaign's ``[keep]``, and what compressing float32 signals would cost and save.

1. Bytes per run: the same campaign (8 × 5 s reduced runs, PBC + sign SMO) stored with
   every signal (the default), every signal compressed (``compress = true``:
   `validation.run.packing`), a named subset (the joints, their references and the tip
   deflections: 6 signals), every 10th sample, and metrics only — the mean run file and
   the index's bytes per run.  The metrics of every choice are checked equal.
2. Compression of a run's float32 signals (5 s at 1 kHz, 62 signals: 1.24 MB) from a
   reduced and a truth-plant run: ratio, write (compress) and read (decompress) time per
   run with the standard library's zlib (levels 1 and 6), lzma (preset 1) and bz2, each on
   the raw bytes, on the bytes shuffled (byte k of every value together) and on the
   shuffled first differences (exact: integer differences of the float32 bit patterns;
   what ``[keep] compress`` stores, with zlib 1);
   and with zstandard (levels 1 and 3) when it is installed (it is not a dependency).
   Medians of 5.
"""
from __future__ import annotations

import bz2
import lzma
import statistics
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

from _report import report
from validation.batch.campaign import campaign_from_mapping
from validation.batch.queue import run_campaign
from validation.batch.store.folder import ResultStore
from validation.batch.worker import execute_run

CAMPAIGN = {"name": "keep", "scenario": {"duration": 5.0, "observer": {"kind": "smo-paper"},
                                         "sensors": {"encoder_noise": 1e-4}},
            "sweep": [{"grid": {"seed": list(range(1, 9))}}]}
CHOICES = {"all signals (default)": {},
           "all signals, compressed": {"compress": True},
           "6 named signals": {"signals": ["theta1", "theta2", "theta1_ref", "theta2_ref",
                                           "tip_defl1", "tip_defl2"]},
           "every 10th sample": {"every": 10},
           "metrics only": {"signals": "none"}}
REPEATS = 5


def bytes_per_run() -> list[dict]:
    rows, tables = [], []
    for label, keep in CHOICES.items():
        with tempfile.TemporaryDirectory() as tmp:
            run_campaign(campaign_from_mapping(dict(CAMPAIGN, keep=keep)), tmp, progress=False)
            store = ResultStore(tmp)
            stored = store.rows()
            tables.append({r.run_id: r.metrics for r in stored})
            files = [r.size for r in stored]
            store.close()
            index = sum(p.stat().st_size for p in Path(tmp).glob("index.sqlite*"))
        rows.append({"what": f"[keep] {label}", "file_bytes": statistics.mean(files),
                     "index_bytes": index / len(files),
                     "total_bytes": statistics.mean(files) + index / len(files)})
    same = all(_same(tables[0], t) for t in tables[1:])
    rows.append({"what": "metrics equal for every choice", "note": "yes" if same else "NO"})
    return rows


def _same(a: dict, b: dict) -> bool:
    nan = lambda v: isinstance(v, float) and v != v  # noqa: E731
    return a.keys() == b.keys() and all(
        x.keys() == y.keys() and all(x[k] == y[k] or (nan(x[k]) and nan(y[k])) for k in x)
        for x, y in ((a[r], b[r]) for r in a))


def _shuffle(values: np.ndarray) -> bytes:
    return values.view(np.uint8).reshape(values.shape[0], -1, 4).transpose(0, 2, 1).tobytes()


def _delta(values: np.ndarray) -> np.ndarray:
    bits = values.view(np.uint32).copy()
    bits[:, 1:] -= values.view(np.uint32)[:, :-1]  # wraps: exact, cumsum undoes it
    return bits


def codecs() -> dict:
    out = {"zlib 1": (lambda b: zlib.compress(b, 1), zlib.decompress),
           "zlib 6": (lambda b: zlib.compress(b, 6), zlib.decompress),
           "lzma 1": (lambda b: lzma.compress(b, preset=1), lzma.decompress),
           "bz2 9": (lambda b: bz2.compress(b, 9), bz2.decompress)}
    try:
        import zstandard
    except ImportError:
        return out
    for level in (1, 3):
        out[f"zstd {level} ({zstandard.__version__})"] = (
            zstandard.ZstdCompressor(level=level).compress,
            zstandard.ZstdDecompressor().decompress)
    return out


def compression() -> list[dict]:
    rows = []
    for plant in ("reduced", "exudyn"):
        result, _ = execute_run({"duration": 5.0, "plant": {"kind": plant},
                                 "observer": {"kind": "smo-paper"},
                                 "sensors": {"encoder_noise": 1e-4}})
        signals = np.ascontiguousarray(result.signals, dtype=np.float32)
        raw = signals.tobytes()
        filters = {"raw": lambda: raw, "shuffled": lambda: _shuffle(signals),
                   "shuffled differences": lambda: _shuffle(_delta(signals))}
        for name, (compress, decompress) in codecs().items():
            for filt, make in filters.items():
                writes, reads = [], []
                for _ in range(REPEATS):
                    t0 = time.perf_counter()
                    packed = compress(make())
                    t1 = time.perf_counter()
                    decompress(packed)
                    reads.append(time.perf_counter() - t1)
                    writes.append(t1 - t0)
                rows.append({"what": f"{plant} 5 s: {name}, {filt}",
                             "ratio": len(packed) / len(raw),
                             "write_ms": 1e3 * statistics.median(writes),
                             "read_ms": 1e3 * statistics.median(reads),
                             "note": f"{len(raw) / 1e6:.2f} MB -> {len(packed) / 1e6:.2f} MB"})
    return rows


def main() -> None:
    report("keep", bytes_per_run(), title="Bytes per stored run, by [keep] (8 x 5 s reduced "
                                          "runs)",
           columns=["what", "file_bytes", "index_bytes", "total_bytes", "note"])
    report("compression", compression(),
           title=f"Compressing a run's float32 signals (medians of {REPEATS})",
           columns=["what", "ratio", "write_ms", "read_ms", "note"])


if __name__ == "__main__":
    main()
