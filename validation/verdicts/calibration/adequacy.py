"""Is the calibrated model adequate?  Residual tests of a fit, per signal and experiment
(``flexarm calibrate``), as a system-identification engineer checks a model before
trusting its parameters (Ljung, *System Identification*, 2nd ed., §16.6; MATLAB's
``resid``).

At the estimate, the weighted residual e = (y_sim − y_meas) / σ of every signal of every
experiment (and of every measured frequency response, real and imaginary parts) is put
to four tests, each with its statistic and threshold:

* **χ²** — is the residual the stated noise?  n·mean(e²) against χ²(n), two-sided: a
  residual larger than the noise (a model error, or noise larger than stated) or smaller
  (noise smaller than stated).
* **noise** — the residual's *white part*: its level from the fourth difference,
  σ̂² = mean((Δ⁴e)²) / 70 (70 = Σ c² of (1, −4, 6, −4, 1)).  A model error of the arm's
  dynamics is smooth at the sample rate and the fourth difference removes it (measured:
  residuals 6-140× the noise of the reduced model on FE data leave σ̂ 0.94-1.06 of the
  stated noise, where the spectrum above a quarter of the sample rate still read 6.5×,
  its leakage), while white noise keeps 70 times its variance.  For white noise
  mean((Δ⁴e)²)/70 has relative standard deviation √(2 Σ γ_l²)/70/√n = 2.29/√n (γ_l the
  autocovariance of the difference filter: 70, −56, 28, −8, 1).
* **whiteness** — the Ljung–Box statistic of the residual's autocorrelation over lags
  1..h (h = 20, at most n/4) against χ²(h): noise is white, a model error is not.
* **inputs** — the residual's correlation with each joint torque over lags 1..h, each
  standardised (√n-scaled, the residual's level), the largest against the normal
  quantile: an input whose effect the model misses leaves its trace in the residual.
  Lags from 1: the torque of a sample is computed from that sample's noisy measurement
  in a closed loop, and is independent only of later noise.

The whiteness and input tests measure the residual's correlations in units of its own
level, or of the stated noise where that is larger: a structure far below the noise the
data are said to carry cannot be told from it, and is not called a model error (without
this, noise-free synthetic data flagged the float32 rounding of their own fit, 1e-5 of
the stated noise).  The price: with the noise stated far too large, a model error below
that level goes unflagged — the χ² test then reads "noise misstated" (too small).

Every test runs at α = 0.01 / (the number of tests) (Bonferroni: the whole family
falses an adequate model once in a hundred fits).  Their verdict, in words, tells the
noise from the model where the data can:

* the residual is correlated or follows the inputs, or exceeds the noise while its white
  part does not: **a model error** (the model is *inadequate*); the noise test says
  whether the noise level is as stated besides;
* the residual is white and independent of the inputs but not at the stated level:
  **the noise level is misstated** (by the factor σ̂), not the model: the intervals use
  the residual's own level.

**Coloured noise.**  A residual that fails the whiteness test may still be measurement
noise: a sensor's filter or mains hum colours it, and its correlation says nothing of
the model.  It is told from a model error as measurement noise is defined — correlated
in time, but not with the inputs, and at the stated level.  Its noise model, an
autoregression (`validation.verdicts.calibration.noise`), whitens it; then

* **inputs** is the input test on the innovations (exact again: the correlation of white
  innovations with any input has variance 1/n — on the correlated residual itself it is
  not, and AR(1) noise of ρ = 0.9 on the right model failed it on one signal in four);
* **level** replaces χ² and the white part: mean(e²) against the stated level with the
  spread the noise model gives it, 2 Σ γ_k²/n (ten times the white one at ρ = 0.9).

A correlated residual that passes both is **coloured noise** (``diagnosis``
"coloured"), the model adequate — unless one of the physics extensions the toolkit has
explains it (`validation.verdicts.calibration.extensions`: a mild Stribeck effect leaves
a correlated residual within 1-1.3 of the noise, which the level test sees only at the
margin); above the stated level it is a model error, below it a misstated noise level.
The intervals then account for the correlation (`validation.verdicts.calibration.
intervals`).

A closed-loop fit (``inputs = "closed-loop"``) simulates its own noise: its residual is
not the measurement noise, and the model is not judged (``model_adequate`` null).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from .noise import WHITE, NoiseModel, fit_noise

__all__ = ["Block", "residual_blocks", "residual_rms", "adequacy", "noise_models",
           "physics_missed", "FAMILY_ALPHA"]

#: The probability that an adequate model is called inadequate (all tests together).
FAMILY_ALPHA = 0.01
#: Lags of the whiteness and input tests (MATLAB's ``resid`` uses 25; at 1 kHz both see
#: a model error at any frequency below 50 Hz).
LAGS = 20
#: Σ c² of the fourth difference, and the relative standard deviation of its mean square
#: (× √n) for white noise (module docstring).
_DIFF4_GAIN = 70.0
_DIFF4_SPREAD = math.sqrt(2 * (70 ** 2 + 2 * (56 ** 2 + 28 ** 2 + 8 ** 2 + 1))) / 70
#: The fewest samples the white-part estimate is made from.
_MIN_SAMPLES = 50


@dataclass(frozen=True)
class Block:
    """One signal's residual at the estimate: ``residual`` in units of its weight
    ``sigma`` [SI]; ``noise`` the declared level (None: none declared); ``inputs`` the
    joint torques (joints, n) of its experiment (None for a frequency response); ``rows``
    where it lies in the residual vector."""

    experiment: str
    signal: str
    residual: np.ndarray
    sigma: float
    noise: float | None
    inputs: np.ndarray | None
    rows: np.ndarray | None = None


def residual_blocks(plan, r: np.ndarray) -> list[Block]:
    """The residual vector ``r`` of a plan at its full horizon (experiments, then
    frequency responses, as `validation.verdicts.calibration.problem` stacks them) cut
    into one `Block` per signal of each experiment and per part of each measured pair."""
    out, offset = [], 0
    index = np.arange(r.size)
    for target in plan.targets:
        exp = target.experiment
        size = len(exp.names) * exp.samples
        block = r[offset:offset + size].reshape(len(exp.names), -1)
        rows = index[offset:offset + size].reshape(len(exp.names), -1)
        offset += size
        out += [Block(exp.name, name, b, float(sigma), float(noise) if noise > 0 else None,
                      exp.torques.T, at) for name, b, sigma, noise, at in
                zip(exp.names, block, target.sigma, target.noise, rows)]
    noise = plan.settings.frf_noise
    for response in plan.responses:
        shape = response.values.shape
        span = slice(offset, offset + 2 * response.values.size)
        e, at = r[span], index[span]
        offset += e.size
        half = e.size // 2
        parts = ((e[:half].reshape(shape), at[:half].reshape(shape)),
                 (e[half:].reshape(shape), at[half:].reshape(shape)))
        out += [Block(response.name, f"{o}/{i} ({part})", values[j], noise, noise, None,
                      where[j])
                for part, (values, where) in zip(("re", "im"), parts)
                for j, (o, i) in enumerate(response.pairs)]
    return out


def residual_rms(plan, blocks: list[Block]) -> dict:
    """RMS of the fitted residual of every signal of every experiment [SI units], next to
    its declared noise level (None: none declared); a frequency response's relative."""
    out: dict[str, dict] = {}
    for b in blocks:
        out.setdefault(b.experiment, {})
        if b.inputs is not None:
            out[b.experiment][b.signal] = {"rms": float(np.sqrt(np.mean(b.residual ** 2))
                                                        * b.sigma), "noise": b.noise}
    for response in plan.responses:
        e = np.concatenate([b.residual for b in blocks if b.experiment == response.name])
        out[response.name] = {"relative_rms": float(np.sqrt(np.mean(e ** 2))
                                                    * plan.settings.frf_noise),
                              "noise": plan.settings.frf_noise}
    return out


# --- the tests -------------------------------------------------------------------------------
def _chi2(e: np.ndarray, alpha: float) -> dict:
    n = e.size
    bounds = [float(scipy.stats.chi2.ppf(q, n) / n) for q in (alpha / 2, 1 - alpha / 2)]
    ratio = float(np.mean(e ** 2))
    return {"statistic": ratio, "threshold": bounds, "passed": bounds[0] <= ratio <= bounds[1],
            "what": "mean square of the residual over the stated noise's (χ², two-sided)"}


def _white_level(e: np.ndarray) -> float:
    """σ̂ / σ: the level of the residual's white part (module docstring)."""
    return float(np.sqrt(np.mean(np.diff(e, 4) ** 2) / _DIFF4_GAIN))


def _noise(e: np.ndarray, alpha: float) -> dict:
    spread = _DIFF4_SPREAD / math.sqrt(e.size - 4) * scipy.stats.norm.ppf(1 - alpha / 2)
    bounds = [math.sqrt(max(1 - spread, 0.0)), math.sqrt(1 + spread)]
    level = _white_level(e)
    return {"statistic": level, "threshold": bounds, "passed": bounds[0] <= level <= bounds[1],
            "what": "level of the residual's white part over the stated noise (4th difference)"}


def _lags(n: int) -> int:
    return max(1, min(LAGS, n // 4))


def _whiteness(e: np.ndarray, floor: float, alpha: float) -> dict:
    n, h = e.size, _lags(e.size)
    x = e - e.mean()
    energy = max(float(x @ x), n * floor ** 2)
    rho = np.array([x[k:] @ x[:-k] for k in range(1, h + 1)]) / (energy or 1.0)
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, h + 1))))
    limit = float(scipy.stats.chi2.ppf(1 - alpha, h))
    return {"statistic": q, "threshold": limit, "passed": q <= limit,
            "what": f"Ljung-Box Q of the residual's autocorrelation, lags 1..{h} (χ²({h}))"}


def _inputs(e: np.ndarray, torques: np.ndarray, floor: float, alpha: float) -> dict:
    n, h = e.size, _lags(e.size)
    x = e - e.mean()
    level = max(math.sqrt(float(x @ x) / n), floor) or 1.0
    moving = [u for u in torques[:, :n] - torques[:, :n].mean(axis=1, keepdims=True)
              if np.any(u)]
    largest = max(abs(float(x[k:] @ u[:-k])) / (level * (math.sqrt(float(u[:-k] @ u[:-k]))
                                                         or 1.0))
                  for u in moving for k in range(1, h + 1))
    limit = float(scipy.stats.norm.ppf(1 - alpha / (2 * h * len(moving))))
    return {"statistic": largest, "threshold": limit, "passed": largest <= limit,
            "what": f"largest standardised correlation with a joint torque, lags 1..{h}"}


def _applicable(block: Block) -> list[str]:
    """The tests that apply to ``block``: whiteness always; χ² where a noise level is
    stated; the white part's level and the inputs for time series (the level from
    enough samples, the inputs where a torque varies)."""
    timed = block.inputs is not None
    kinds = ["whiteness"] + (["chi2"] if block.noise is not None else [])
    if timed and block.noise is not None and block.residual.size >= _MIN_SAMPLES:
        kinds.append("noise")
    if timed and np.any(np.ptp(block.inputs[:, :block.residual.size], axis=1) > 0):
        kinds.append("inputs")
    return kinds


def _level(e: np.ndarray, model: NoiseModel, alpha: float) -> dict:
    spread = model.mean_square_spread(e.size) * scipy.stats.norm.ppf(1 - alpha / 2)
    bounds = [max(1 - spread, 0.0), 1 + spread]
    ratio = float(np.mean(e ** 2))
    return {"statistic": ratio, "threshold": bounds,
            "passed": bool(bounds[0] <= ratio <= bounds[1]),
            "what": "mean square of the residual over the stated noise's, with the spread "
                    f"its noise model AR({model.order}) gives it (two-sided)"}


def _coloured(block: Block) -> bool:
    """Whether a block's correlated residual is judged as possibly coloured noise: a
    time series with a stated level and enough samples to fit its noise model."""
    return block.inputs is not None and block.noise is not None and \
        block.residual.size >= _MIN_SAMPLES


def _tests(block: Block, alpha: float) -> dict:
    e = block.residual
    floor = 1.0 if block.noise is not None else 0.0  # the stated noise, in weight units
    run = {"whiteness": lambda: _whiteness(e, floor, alpha), "chi2": lambda: _chi2(e, alpha),
           "noise": lambda: _noise(e, alpha),
           "inputs": lambda: _inputs(e, block.inputs, floor, alpha)}
    kinds = _applicable(block)
    tests = {"whiteness": run["whiteness"]()}
    if tests["whiteness"]["passed"] or not _coloured(block):
        return tests | {kind: run[kind]() for kind in kinds if kind != "whiteness"}, None
    model = fit_noise(e)
    tests["level"] = _level(e, model, alpha)
    if "noise" in kinds:
        tests["noise"] = run["noise"]()
    if "inputs" in kinds:
        tests["inputs"] = _inputs(model.whiten(e), block.inputs[:, model.order:],
                                  math.sqrt(model.innovation) if floor else 0.0, alpha)
        tests["inputs"]["what"] += " (of the innovations of its noise model)"
    return tests, model


def _described(model: NoiseModel) -> dict:
    """A noise model in calibration.json: its order, coefficients, the innovations'
    variance and the process's (in units of the weight, the stated level's square)."""
    return {"order": model.order, "coefficients": [float(a) for a in model.coefficients],
            "innovation_variance": model.innovation, "variance": model.variance}


def _diagnosis(tests: dict) -> str:
    """"adequate", "noise" (the stated level is wrong, the model is not), "coloured"
    (correlated measurement noise at the stated level) or "model"."""
    failed = {k for k, t in tests.items() if not t["passed"]}
    if "level" in tests:  # a correlated residual, judged as possibly coloured noise
        if "inputs" in failed:
            return "model"
        if "level" in failed:
            high = tests["level"]["statistic"] > tests["level"]["threshold"][1]
            return "model" if high else "noise"
        return "coloured"
    if failed & {"whiteness", "inputs"}:
        return "model"
    if "chi2" in failed:
        high = tests["chi2"]["statistic"] > tests["chi2"]["threshold"][1]
        return "model" if high and "noise" in tests and tests["noise"]["passed"] else "noise"
    return "noise" if "noise" in failed else "adequate"


def noise_models(blocks: list[Block], verdict: dict) -> list[NoiseModel]:
    """Each block's noise model (in units of its weight): the autoregression of a
    residual judged correlated noise (coloured, at the stated level or not); white at
    its white part's level where the residual is a model error (the model error is not
    noise: an autoregression would whiten it away); else white at the residual's own
    level."""
    out = []
    for b in blocks:
        tests = verdict["signals"][b.experiment][b.signal]
        if "noise_model" in tests and tests["diagnosis"] != "model":
            out.append(fit_noise(b.residual))
        elif tests["diagnosis"] == "model" and b.inputs is not None and \
                b.residual.size >= _MIN_SAMPLES:
            out.append(NoiseModel(WHITE.coefficients, _white_level(b.residual) ** 2))
        else:
            out.append(NoiseModel(WHITE.coefficients, float(np.mean(b.residual ** 2))))
    return out


def adequacy(blocks: list[Block], *, judged: bool = True) -> dict:
    """The tests of every block and the verdict on the model (module docstring).

    Parameters
    ----------
    blocks : list of Block
        The residual at the estimate (`residual_blocks`).
    judged : bool
        False for a closed-loop fit: the tests are reported, the model not judged.

    Returns
    -------
    dict
        ``model_adequate`` (bool, or None when not judged), ``noise_as_stated`` (bool, or
        None where no level is declared), ``verdict`` (one line), ``failing`` (each failed
        test in words), ``family_alpha``, ``signals`` (experiment → signal → test →
        ``statistic, threshold, passed, what``, and ``diagnosis``), ``model_error`` (the
        norm of the residual beyond its white part, in units of the weights) and
        ``noise_variance`` (the white part's mean square, pooled).
    """
    alpha = FAMILY_ALPHA / max(1, sum(len(_applicable(b)) for b in blocks))
    signals: dict[str, dict] = {}
    failing, by_kind = [], {"model": [], "noise": [], "coloured": []}
    excess = white = samples = 0.0
    for b in blocks:
        tests, model = _tests(b, alpha)
        diagnosis = _diagnosis(tests)
        entry = {**tests, "diagnosis": diagnosis}
        if model is not None:
            entry["noise_model"] = _described(model)
        signals.setdefault(b.experiment, {})[b.signal] = entry
        for kind, t in tests.items():
            if not t["passed"] and _counts(kind, model is not None, diagnosis):
                failing.append(f"{b.experiment}/{b.signal}: {kind} {t['statistic']:.4g} "
                               f"(threshold {_threshold_text(t['threshold'])})")
        if diagnosis != "adequate":
            by_kind[diagnosis].append(b)
        # the white part: estimated where it can be, else the stated level; coloured
        # noise is noise throughout
        level2 = float(np.mean(b.residual ** 2)) if diagnosis == "coloured" else \
            _white_level(b.residual) ** 2 if b.inputs is not None and \
            b.residual.size >= _MIN_SAMPLES else 1.0
        excess += max(0.0, float(b.residual @ b.residual) - b.residual.size * level2)
        white += b.residual.size * level2
        samples += b.residual.size
    levels = [t[_level_test(t)]["passed"] for s in signals.values() for t in s.values()
              if _level_test(t) in t]
    noise_ok = all(levels) if levels else None
    adequate = not by_kind["model"] if judged else None
    return {"model_adequate": adequate, "noise_as_stated": noise_ok,
            "noise_coloured": bool(by_kind["coloured"]) or any(
                "noise_model" in t for s in signals.values() for t in s.values()),
            "verdict": _verdict(adequate, by_kind, signals, judged),
            "failing": failing, "family_alpha": FAMILY_ALPHA, "test_alpha": alpha,
            "signals": signals, "model_error": math.sqrt(excess),
            "noise_variance": white / samples if samples else 1.0}


def _counts(kind: str, correlated: bool, diagnosis: str) -> bool:
    """Whether a failed test of a block says something of the model or the noise: of a
    correlated residual judged as possibly coloured noise, the whiteness test does not
    (its correlation is what is judged), nor does the white part unless the residual is
    a model error (the white part of coloured noise is not its level)."""
    if not correlated:
        return True
    return kind in ("inputs", "level") or (kind == "noise" and diagnosis == "model")


def _level_test(tests: dict) -> str:
    """The test that reads a block's noise level: its white part, unless its residual
    is correlated and not a model error (then its level as a whole)."""
    return "level" if "level" in tests and tests["diagnosis"] != "model" else "noise"


def _threshold_text(threshold) -> str:
    if isinstance(threshold, list):
        return f"{threshold[0]:.4g}..{threshold[1]:.4g}"
    return f"{threshold:.4g}"


def _verdict(adequate, by_kind: dict, signals: dict, judged: bool) -> str:
    def names(blocks):
        return ", ".join(f"{b.experiment}/{b.signal}" for b in blocks[:6]) + \
            (f" and {len(blocks) - 6} more" if len(blocks) > 6 else "")

    def levels(blocks):
        found = []
        for b in blocks:
            tests = signals[b.experiment][b.signal]
            kind = _level_test(tests)
            if kind in tests:
                value = tests[kind]["statistic"]
                found.append(f"{b.signal} {math.sqrt(value) if kind == 'level' else value:.3g}×")
        return ", ".join(found[:6])

    def coloured(blocks):
        return ", ".join(f"{b.signal} AR({signals[b.experiment][b.signal]['noise_model']['order']})"
                         for b in blocks[:6])

    misstated = [b for kind in ("model", "noise") for b in by_kind[kind]
                 if _level_test(signals[b.experiment][b.signal]) in signals[b.experiment][b.signal]
                 and not signals[b.experiment][b.signal][
                     _level_test(signals[b.experiment][b.signal])]["passed"]]
    if not judged:
        return ("not judged: a closed-loop fit simulates its own noise, so its residual is "
                "not the measurement noise (fit with inputs = \"replay\" to judge the model)")
    if not adequate:
        text = (f"MODEL INADEQUATE: the residual of {names(by_kind['model'])} is correlated, "
                "follows the inputs or exceeds the noise beyond its white part: the estimates "
                "are effective parameters of this model, not physical values")
        return text + (f"; the noise levels are misstated too (white part: {levels(misstated)})"
                       if misstated else "; the noise levels are as stated")
    if by_kind["noise"]:
        return (f"model adequate, noise misstated: the residual of {names(by_kind['noise'])} "
                "does not follow the inputs but is not at the stated level"
                + (f" (its level: {levels(misstated)} the stated noise)" if misstated else "")
                + ": the noise level is wrong, not the model; the intervals use the "
                  "residual's own level")
    if by_kind["coloured"]:
        return (f"model adequate, noise coloured: the residual of {names(by_kind['coloured'])} "
                f"is correlated in time ({coloured(by_kind['coloured'])}) but does not follow "
                "the inputs and is at the stated level: coloured measurement noise, not a "
                "model error; the intervals account for its correlation")
    return ("model adequate: the residual is white noise at the stated levels, independent "
            "of the inputs")


def physics_missed(verdict: dict, found: dict) -> dict:
    """The verdict on a model whose correlated residual passed as coloured noise but
    follows the signature of a physics extension (``found``: its screen, significant):
    inadequate, naming it."""
    line = (f"{found['name']}: screen {found['score']:.4g} (threshold "
            f"{found['threshold']:.4g})")
    return {**verdict, "model_adequate": False, "failing": verdict["failing"] + [line],
            "verdict": ("MODEL INADEQUATE: the residual is correlated at the stated level "
                        "and does not follow the inputs, but it follows the signature of "
                        f"{found['name']} ({line}): a model error, not coloured noise; the "
                        "estimates are effective parameters of this model")}
