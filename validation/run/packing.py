"""Run files' signals compressed without loss: the float32 values of each signal as the
differences of their bit patterns from one sample to the next (integers modulo 2³²:
undone exactly by a cumulative sum), their bytes shuffled (the k-th byte of every value
together: smooth signals differ mostly in the low bytes), then zlib at level 1 (the
standard library; measured in ``bench/bench_keep.py``: about half the bytes of a 5 s
closed-loop run, ~20 ms per run to write, ~5 ms to read)."""
from __future__ import annotations

import zlib

import numpy as np

__all__ = ["CODEC", "pack", "unpack", "MAX_UNPACKED"]

#: The name a run file's metadata gives this packing.
CODEC = "float32-differences-shuffled-zlib1"
#: The most bytes a packed signals array may declare (a crafted file could declare more).
MAX_UNPACKED = 1 << 32


def pack(signals: np.ndarray) -> bytes:
    """The packed bytes of float32 ``signals`` (n_signals, n_samples)."""
    bits = np.ascontiguousarray(signals, dtype=np.float32).view(np.uint32)
    steps = bits.copy()
    steps[:, 1:] -= bits[:, :-1]  # wraps modulo 2**32
    n, m = steps.shape
    shuffled = steps.view(np.uint8).reshape(n, m, 4).transpose(0, 2, 1)
    return zlib.compress(np.ascontiguousarray(shuffled).tobytes(), 1)


def unpack(data: bytes, shape) -> np.ndarray:
    """The float32 signals of shape ``shape`` that `pack` made ``data`` from; ValueError
    unless ``data`` unpacks to exactly that many values (never more is inflated)."""
    n, m = (int(k) for k in shape)
    size = 4 * n * m
    if n < 0 or m < 0 or size > MAX_UNPACKED:
        raise ValueError(f"packed signals of shape {tuple(shape)}: not a run's")
    inflate = zlib.decompressobj()
    raw = inflate.decompress(data, size)
    if len(raw) != size or inflate.unconsumed_tail or not inflate.eof:
        raise ValueError(f"packed signals do not hold {n} x {m} values")
    steps = np.frombuffer(raw, np.uint8).reshape(n, 4, m).transpose(0, 2, 1)
    steps = np.ascontiguousarray(steps).view(np.uint32).reshape(n, m)
    return np.cumsum(steps, axis=1, dtype=np.uint32).view(np.float32)
