"""Vibration of a run's tip deflections: the oscillatory part the paper's vibration claim
is about, separated from the quasi-static bending the motion demands.

**Vibration** is the oscillatory part of a tip deflection, separated from the
  quasi-static bending the motion itself demands: the deflection high-passed at
  ``VIBRATION_CUTOFF`` × the arm's first natural frequency with the joints locked
  (0.8 × 0.632 = 0.51 Hz for the default arm), by a 4th-order Butterworth filter run
  forward and backward (zero phase).  The paper's reference has its fundamentals at 0.05
  and 0.1 Hz; the bending it demands (centrifugal and inertial loads, products of the two)
  stays below 0.4 Hz, where the filter passes ≤ 15 % of the amplitude, while at the first
  mode it passes ≥ 85 %.  ``vib_rms_i`` is its RMS after the transient.

**Vibration decay**: the oscillatory deflection's RMS per ``VIBRATION_WINDOW`` (2 s)
  window from t = 0 (``vib_win_i_TT``, TT the window's start in s); the decay rate right
  after the transient ``vib_decay_i`` [1/s] = ln(RMS of the first full window from the
  transient ÷ RMS of the next) / 2 s (1.15/s: ten-fold in 2 s; 0: it does not decay);
  and ``vib_late_i``, the RMS over the second half of the run: what stays.  A start-up
  kick that dies out and a vibration that stays can have the same RMS after a transient;
  these tell them apart.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from reduced_model import ArmParameters

from .reductions import after, as_float, peak, per_joint, rms

__all__ = ["vibration", "vibration_decay", "vibration_cutoff", "oscillatory",
           "VIBRATION_CUTOFF", "VIBRATION_WINDOW"]

#: The vibration high-pass sits at this fraction of the first locked natural frequency.
VIBRATION_CUTOFF = 0.8
#: Length [s] of the windows of the vibration's decay (module docstring): 1.3 periods of
#: the first mode at 0.63 Hz, 10 windows in the paper's 20 s.
VIBRATION_WINDOW = 2.0


def vibration_cutoff(params: ArmParameters) -> float:
    """The vibration high-pass frequency [Hz] for an arm (module docstring); NaN for an
    arm of rigid links only (it has no vibration)."""
    from .laws import nominal_model
    frequencies = nominal_model(params, None).natural_frequencies()
    return VIBRATION_CUTOFF * float(frequencies[0]) if frequencies.size else math.nan


@functools.lru_cache(maxsize=64)  # every run of an arm at one Ts designs the same filter
def _highpass(normalised_cutoff: float) -> np.ndarray:
    from scipy.signal import butter  # 0.4 s to import: not on every command's start
    sos = butter(4, normalised_cutoff, "highpass", output="sos")
    sos.flags.writeable = False
    return sos


def oscillatory(result, cutoff_hz: float) -> np.ndarray:
    """The tip deflections' oscillatory part (N, n_samples): zero-phase high-pass."""
    w = as_float(result, per_joint(result, "tip_defl{}"))
    dt = result.time[1] - result.time[0]
    nyquist = 0.5 / dt
    sos = _highpass(min(cutoff_hz / nyquist, 0.99)).copy()  # scipy wants it writable
    padlen = min(3 * (2 * len(sos) + 1), w.shape[1] - 1)
    from scipy.signal import sosfiltfilt
    return sosfiltfilt(sos, w, axis=1, padlen=padlen)


def vibration(result, transient: float, cutoff_hz: float) -> dict[str, float]:
    """The oscillatory tip deflection (module docstring) after ``transient``, and its
    decay (`vibration_decay`).

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].
    cutoff_hz : float
        The high-pass frequency that separates vibration from quasi-static bending [Hz].

    Returns
    -------
    vib_cutoff_hz : float
        That frequency [Hz].
    vib_rms_i : float
        RMS of link i's oscillatory tip deflection after the transient [m].
    vib_max_i : float
        Its max after the transient [m].
    """
    late = after(result, transient)
    out = {"vib_cutoff_hz": cutoff_hz}
    links = len(per_joint(result, "{}"))
    if result.time.size < 16 or not late.any() or not math.isfinite(cutoff_hz):
        return out | {f"vib_{k}_{i}": math.nan for k in ("rms", "max")
                      for i in range(1, links + 1)}
    v = oscillatory(result, cutoff_hz)
    late_rms, mx = rms(v[:, late]), peak(v[:, late])
    return out | {f"vib_rms_{i + 1}": float(late_rms[i]) for i in range(links)} | \
        {f"vib_max_{i + 1}": float(mx[i]) for i in range(links)} | \
        vibration_decay(result.time, v, transient)


def vibration_decay(time: np.ndarray, oscillation: np.ndarray, transient: float) -> dict:
    """Per link: how the oscillatory tip deflection decays (module docstring); NaN where
    the run is too short.

    Parameters
    ----------
    time : ndarray
        Sample times [s].
    oscillation : ndarray
        The oscillatory tip deflections (N, n_samples) [m].
    transient : float
        Where the decay is measured from [s].

    Returns
    -------
    vib_win_i_TT : float
        RMS of link i's oscillation in the full `VIBRATION_WINDOW` starting at TT
        seconds [m].
    vib_decay_i : float
        Decay rate between the first two windows that start at or after the transient
        [1/s] (ln of their RMS ratio ÷ the window).
    vib_late_i : float
        RMS over the run's second half: what stays [m].
    """
    dt = time[1] - time[0]
    k = max(1, int(round(VIBRATION_WINDOW / dt)))
    n = time.size // k
    starts = time[0] + VIBRATION_WINDOW * np.arange(n)
    first = int(np.searchsorted(starts, transient - 1e-9))
    second_half = time >= time[0] + 0.5 * (time[-1] - time[0])
    out = {}
    for i in range(oscillation.shape[0]):
        windows = np.array([rms(oscillation[i, j * k:(j + 1) * k]) for j in range(n)])
        out |= {f"vib_win_{i + 1}_{s:02.0f}": float(r) for s, r in zip(starts, windows)}
        pair = windows[first:first + 2]
        out[f"vib_decay_{i + 1}"] = (float(np.log(pair[0] / pair[1]) / VIBRATION_WINDOW)
                                     if pair.size == 2 and np.all(pair > 0) else math.nan)
        out[f"vib_late_{i + 1}"] = float(rms(oscillation[i, second_half]))
    return out
