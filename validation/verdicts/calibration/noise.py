"""The noise model of a calibration's residual: white, or coloured — an autoregressive
process fitted to it (``flexarm calibrate``).

A sensor's noise need not be white: a filtered encoder, a strain gauge amplifier with a
low-pass, mains hum.  Such noise leaves a residual correlated in time that a model error
also leaves; what tells them apart is that measurement noise does not follow the inputs
and stays at the stated level (`validation.verdicts.calibration.adequacy`).  Both need
the noise's correlation: its model is an autoregression

    e_t = a_1 e_{t−1} + … + a_p e_{t−p} + ε_t,      ε white, variance s²,

of order p ≤ `MAX_ORDER` chosen by BIC (n ln s²_p + p ln n; Schwarz 1978), fitted to
each signal's residual by the Yule–Walker equations (Levinson–Durbin: every order at
once).  It whitens the residual (the innovations ε, on
which the input and whiteness tests are exact again: a correlation of white ε with any
input has variance 1/n), gives the variance of the residual's mean square (the χ² test
of its level: Var(mean e²) = 2 Σ_k γ_k² / n for a Gaussian process, γ its autocovariance),
and the covariance of the estimate (`intervals`): the least-squares estimate is
unchanged by the noise's colour, its covariance is the sandwich
(JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹ with Σ = s² A⁻¹A⁻ᵀ (A the whitening filter), computed by filtering
J's columns backwards through 1/A — for smooth columns it is the white covariance
times the noise's spectral density at low frequency, (1+ρ)/(1−ρ) = 19 for AR(1) noise
of ρ = 0.9 (its standard errors 4.4 times the white ones).

`MAX_ORDER` = 30: AR(1) noise of ρ = 0.9 is found as order 1 (ρ̂ 0.89-0.91 on four
signals of 2000 samples), a 50 Hz hum (half the stated variance, sampled at 1 kHz) under
white noise as order 21-22 — an autoregression needs about its period to represent a
sinusoid beside white noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal

__all__ = ["NoiseModel", "fit_noise", "sandwich_meat", "WHITE", "MAX_ORDER"]

#: The highest order of the autoregression (module docstring).
MAX_ORDER = 30
#: Lags of the autocovariance summed for the variance of a mean square: beyond them a
#: stable autoregression of the orders fitted here has decayed below 1e-6 of its peak.
_HORIZON = 4000


@dataclass(frozen=True)
class NoiseModel:
    """e_t = Σ a_k e_{t−k} + ε_t with Var ε = ``innovation`` (module docstring); no
    coefficients: white noise of variance ``innovation``."""

    coefficients: np.ndarray
    innovation: float

    @property
    def order(self) -> int:
        return len(self.coefficients)

    @property
    def filter(self) -> np.ndarray:
        """A(q): the whitening filter's coefficients (1, −a_1, …, −a_p)."""
        return np.concatenate([[1.0], -self.coefficients])

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """The innovations of ``x`` (its first p samples dropped: they have no past)."""
        return scipy.signal.lfilter(self.filter, [1.0], x)[self.order:]

    def autocovariance(self, lags: int = _HORIZON) -> np.ndarray:
        """γ_0 … γ_{lags−1} of the process."""
        impulse = scipy.signal.lfilter([1.0], self.filter, np.r_[1.0, np.zeros(lags - 1)])
        full = np.correlate(impulse, impulse, "full")[impulse.size - 1:]
        return self.innovation * full[:lags]

    @property
    def variance(self) -> float:
        """γ_0: the variance of the process."""
        return float(self.autocovariance(1 if not self.order else _HORIZON)[0])

    def mean_square_spread(self, n: int) -> float:
        """The standard deviation of mean(e²) over n samples, relative to γ_0."""
        gamma = self.autocovariance(1 if not self.order else _HORIZON)
        rho = gamma / gamma[0]
        return math.sqrt(2.0 * (1.0 + 2.0 * float(np.sum(rho[1:] ** 2))) / n)

    def backwards(self, columns: np.ndarray) -> np.ndarray:
        """A⁻ᵀ applied to ``columns`` (n, k), scaled by √s²: the rows whose Gram matrix is
        JᵀΣJ (module docstring)."""
        if not self.order:
            return columns * math.sqrt(self.innovation)
        reversed_ = scipy.signal.lfilter([1.0], self.filter, columns[::-1], axis=0)
        return reversed_[::-1] * math.sqrt(self.innovation)


#: The stated noise, white (in units of the weights).
WHITE = NoiseModel(np.zeros(0), 1.0)


def fit_noise(e: np.ndarray, max_order: int = MAX_ORDER) -> NoiseModel:
    """The autoregression of ``e`` (one signal's residual, in units of its weight) of the
    order BIC chooses up to ``max_order`` (at most an eighth of the samples), every
    order's coefficients and innovation variance from the Yule–Walker equations of the
    sample autocovariance by the Levinson–Durbin recursion (a stable process at every
    order)."""
    e = np.asarray(e, dtype=float)
    n = e.size
    top = min(max_order, n // 8)
    x = e - e.mean()
    gamma = np.array([x[k:] @ x[:n - k] for k in range(top + 1)]) / n
    if gamma[0] <= 0:
        return NoiseModel(np.zeros(0), float(e @ e) / max(n, 1))
    a, s2 = np.zeros(0), gamma[0]
    best = (n * math.log(s2), a, s2)
    for p in range(1, top + 1):
        k = (gamma[p] - a @ gamma[1:p][::-1]) / s2
        a = np.concatenate([a - k * a[::-1], [k]])
        s2 *= 1.0 - k * k
        if s2 <= 0:
            break
        score = n * math.log(s2) + p * math.log(n)
        if score < best[0]:
            best = (score, a, s2)
    return NoiseModel(best[1], float(best[2]))


def sandwich_meat(J: np.ndarray, rows, models) -> np.ndarray:
    """JᵀΣJ for a residual whose signals ``rows`` (index arrays into J's rows) carry
    independent noises ``models`` (module docstring)."""
    meat = np.zeros((J.shape[1], J.shape[1]))
    for at, model in zip(rows, models):
        B = model.backwards(J[at])
        meat += B.T @ B
    return meat
