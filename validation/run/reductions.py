"""The reductions every metric of a run uses: its samples after a time, RMS and peak
along the last axis (NaN for no samples), signals as float64, and the arm's joints read
from the signals."""
from __future__ import annotations

import numpy as np

__all__ = ["after", "rms", "peak", "as_float", "joints_of", "per_joint"]


def after(result, start: float) -> np.ndarray:
    return result.time >= start - 1e-12


def rms(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis)) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def peak(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.max(np.abs(x), axis=axis) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def as_float(result, names) -> np.ndarray:
    return result.select(list(names)).astype(float)


def joints_of(result) -> int:
    """The joints N of a run's arm (its reference angles ``theta<i>_ref``)."""
    return sum(1 for name in result.names if name.startswith("theta") and name.endswith("_ref")
               and name[5:-4].isdigit())


def per_joint(result, pattern: str) -> list[str]:
    """``pattern`` (with ``{}`` for the joint or link number) for each joint from 1."""
    return [pattern.format(i) for i in range(1, joints_of(result) + 1)]
