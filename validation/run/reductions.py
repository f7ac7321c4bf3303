"""The reductions every metric of a run uses: its samples after a time, RMS and peak
along the last axis (NaN for no samples), and signals as float64."""
from __future__ import annotations

import numpy as np

__all__ = ["after", "rms", "peak", "as_float"]


def after(result, start: float) -> np.ndarray:
    return result.time >= start - 1e-12


def rms(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis)) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def peak(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.max(np.abs(x), axis=axis) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def as_float(result, names) -> np.ndarray:
    return result.select(list(names)).astype(float)
