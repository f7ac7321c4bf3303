"""Experiment data: what a lab (or a stored run standing in for one) measured, read and
checked before a calibration uses it (``flexarm calibrate``, ``flexarm export --signals``).

An experiment is a CSV file::

    # comment lines (a label, where the data come from) start with '#'
    t,tau1,tau2,theta1,theta2,q11,...
    0.0,0.731,0.112,0.0,0.0,1.2e-6,...

``t`` [s] at a constant sample period (the scenario's ``Ts``), ``tau1`` … ``tauN`` [N m],
one per joint of the arm: the joint torques applied over [t_k, t_k+1) (everything the
joints received), and any
readings of the scenario's sensor model by its own names and SI units — ``theta1``,
``theta2`` [rad], the modal coordinates ``q11``… (as the sensors derive them), rates
``theta1_dot``… [rad/s, m/s], ``tip_x``, ``tip_y`` [m] — each measured at t_k, before
the torque of that sample acts (as the closed loop records its ``y_*`` signals).  A
stored run reads the same way (`from_run`): its applied torques plus disturbances, and
its measurements.

A frequency response (``--frf``) is a CSV with ``f`` [Hz] and, for each measured pair, the
real and imaginary parts of the response of an output to a joint torque, in the linear
models' names and SI units per N m: ``theta1/tau1.re``, ``theta1/tau1.im``,
``q11/tau2.re``… (`FrequencyResponse`).

Every defect is a `ConfigError` naming the file and the column: a missing column, a
name no sensor gives, a value that is not a finite number, time that does not increase
by one constant period, fewer than two samples, values no arm in SI units can have
(angles beyond the scenario's divergence bound, a time step that is not the control
period — data in degrees or milliseconds).
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import ConfigError, check
from .results import RunResult

__all__ = ["Experiment", "read_experiment", "from_run", "write_experiment", "check_experiment",
           "FrequencyResponse", "read_frequency_response", "torque_columns"]
#: Relative tolerance on the sample period: the text of a CSV keeps 9+ digits.
_PERIOD_RTOL = 1e-6
#: The largest file read [bytes] (a 20 s record at 1 kHz with 14 signals is ~5 MB).
MAX_BYTES = 256 << 20


@dataclass(frozen=True)
class Experiment:
    """One experiment: samples at t_k = k·Ts (k = 0…N−1).

    Attributes
    ----------
    name : str
        Its label (the file's stem, or the run's id).
    source : str
        Where it was read from (for messages).
    Ts : float
        Sample period [s].
    torques : ndarray (N, joints)
        Joint torques applied over [t_k, t_k+1) [N m].
    names : tuple of str
        The measured signals, by the sensor model's names.
    signals : ndarray (len(names), N)
        Their values at t_k (SI units).
    """

    name: str
    source: str
    Ts: float
    torques: np.ndarray
    names: tuple[str, ...]
    signals: np.ndarray

    @property
    def samples(self) -> int:
        return self.torques.shape[0]

    @property
    def duration(self) -> float:
        """N·Ts [s]: the span a run of N samples simulates."""
        return self.samples * self.Ts

    def column(self, name: str) -> str:
        """How messages name a column of this experiment."""
        return f"{self.source}: column {name}"


def torque_columns(joints: int) -> tuple[str, ...]:
    """The torque columns of an experiment on an arm of ``joints`` joints: tau1 … tauN."""
    return tuple(f"tau{i}" for i in range(1, joints + 1))


def _float(text: str, where: str, row: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(where, f"row {row}: {text.strip()[:30]!r} is not a number") from None
    check(math.isfinite(value), where, f"row {row}: {text.strip()!r} is not finite")
    return value


def _read_table(path: Path) -> dict[str, np.ndarray]:
    """The columns of a CSV file (a header line, then numbers; '#' lines are comments),
    each checked finite; `ConfigError` naming the file and column."""
    src = str(path)
    check(path.is_file(), src, "no such file")
    check(path.stat().st_size <= MAX_BYTES, src, f"larger than {MAX_BYTES >> 20} MiB")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(src, f"cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    check(bool(lines), src, "no header line")
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    header = [h.strip() for h in rows[0]]
    for col in header:
        check(col != "", src, "an empty column name in the header")
        check(header.count(col) == 1, f"{src}: column {col}", "appears more than once")
    data = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:]):
        check(len(row) == len(header), src, f"row {i + 1}: {len(row)} values for "
                                            f"{len(header)} columns")
        for j, cell in enumerate(row):
            data[i, j] = _float(cell, f"{src}: column {header[j]}", i + 1)
    return {c: data[:, j] for j, c in enumerate(header)}


def read_experiment(path: str | Path, name: str | None = None) -> Experiment:
    """Read an experiment CSV (format in the module docstring).

    Parameters
    ----------
    path : path-like
        The CSV file: columns ``t``, ``tau1`` … ``tauN`` and the measured signals.
    name : str, optional
        The experiment's name; the file's stem by default.

    Returns
    -------
    Experiment

    Raises
    ------
    ConfigError
        Naming the file and column of any defect.
    """
    path = Path(path)
    src = str(path)
    columns = _read_table(path)
    joints = 0
    while f"tau{joints + 1}" in columns:
        joints += 1
    for col in ("t", "tau1"):
        check(col in columns, f"{src}: column {col}", "missing (an experiment needs t [s], "
                                                      "one torque per joint tau1, tau2, … "
                                                      "[N m] and its measurements)")
    inputs = ("t", *torque_columns(joints))
    measured = tuple(c for c in columns if c not in inputs)
    check(bool(measured), src, "no measured signal (columns besides t and the torques)")
    t = columns["t"]
    where = f"{src}: column t"
    check(len(t) >= 2, where, f"{len(t)} sample(s): an experiment needs at least two (one "
                              "control period)")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = bad[0]
        raise ConfigError(where, f"time does not increase at row {k + 2} (t = {t[k + 1]:g} s "
                                 f"after {t[k]:g} s)")
    Ts = float((t[-1] - t[0]) / (len(t) - 1))
    uneven = np.flatnonzero(np.abs(dt - Ts) > _PERIOD_RTOL * Ts)
    if uneven.size:
        k = uneven[0]
        raise ConfigError(where, f"the sample period is not constant (row {k + 2}: step "
                                 f"{dt[k]:g} s, mean {Ts:g} s)")
    return Experiment(name=name or path.stem, source=src, Ts=Ts,
                      torques=np.column_stack([columns[c] for c in inputs[1:]]),
                      names=measured, signals=np.array([columns[c] for c in measured]))


def from_run(result: RunResult, name: str, source: str) -> Experiment:
    """A stored run as an experiment: the torques the joints received (the law's,
    saturated, plus joint disturbances) and its measurements (``y_*``, noise and delay
    included); a run that did not complete is refused."""
    check(result.status == "ok", source, f"the run {result.status} ({result.message}): only "
                                         "a completed run is an experiment")
    check(len(result.time) >= 2, source, "fewer than two samples")
    names = tuple(n.removeprefix("y_") for n in result.names_with("y_"))
    joints = len(result.names_with("dist_tau"))
    torques = np.column_stack([result[tau] + result[f"dist_{tau}"]
                               for tau in torque_columns(joints)]).astype(np.float64)
    return Experiment(name=name, source=source, Ts=float(result.config["Ts"]),
                      torques=torques, names=names,
                      signals=result.select([f"y_{n}" for n in names]).astype(np.float64))


def write_experiment(exp: Experiment, fh, comment: str = "", *, digits: int = 9) -> None:
    """Write ``exp`` as an experiment CSV to the text file ``fh`` (``comment``: lines
    written first, each as a '#' line).  Values with ``digits`` significant digits: with
    9, every float32 the store keeps reads back exactly."""
    for line in comment.splitlines():
        fh.write(f"# {line}\n".replace("# \n", "#\n"))
    fh.write(",".join(("t", *torque_columns(exp.torques.shape[1]), *exp.names)) + "\n")
    t = np.arange(exp.samples) * exp.Ts
    table = np.column_stack([t, exp.torques, exp.signals.T])
    for row in table:
        fh.write(",".join(f"{v:.{digits}g}" for v in row) + "\n")


def check_experiment(exp: Experiment, scenario, measurable: tuple[str, ...]) -> None:
    """Check ``exp`` against the scenario it is fitted with: its sample period is the
    control period, it measures only what the sensors give (``measurable``), and its
    values have SI magnitudes an arm within the scenario's divergence bounds can have, with
    one torque per joint of its arm."""
    arm = scenario.true_params
    given = exp.torques.shape[1]
    check(given >= arm.n_links, exp.column(f"tau{given + 1}"), f"missing (the arm has "
          f"{arm.n_links} joints: one torque per joint, "
          f"{', '.join(torque_columns(arm.n_links))})")
    check(given <= arm.n_links, exp.column(f"tau{arm.n_links + 1}"),
          f"a torque of joint {arm.n_links + 1}: the arm has {arm.n_links} joints")
    check(math.isclose(exp.Ts, scenario.Ts, rel_tol=_PERIOD_RTOL), exp.column("t"),
          f"sample period {exp.Ts:g} s is not the scenario's Ts = {scenario.Ts:g} s (time in "
          "seconds, one row per control period)")
    for name in exp.names:
        check(name in measurable, exp.column(name),
              f"not a measurement of the scenario's sensors (measured: {', '.join(measurable)})")
    div = scenario.divergence
    joints = range(1, arm.n_links + 1)
    bounds = {f"theta{i}": div.max_angle for i in joints} | \
        {f"theta{i}_dot": div.max_rate for i in joints}
    reach = sum(link.length for link in arm.links)
    bounds |= {"tip_x": 2 * reach, "tip_y": 2 * reach}
    for name, values in zip(exp.names, exp.signals):
        if name in bounds:
            worst = float(np.abs(values).max())
            unit = "rad/s" if name.endswith("_dot") else "m" if name.startswith("tip") else "rad"
            check(worst <= bounds[name], exp.column(name),
                  f"|value| reaches {worst:.4g}, beyond the {bounds[name]:g} {unit} any run of "
                  f"the scenario can reach: not in {unit}?")


@dataclass(frozen=True)
class FrequencyResponse:
    """Measured frequency responses (module docstring).

    Attributes
    ----------
    name, source : str
        Label and file.
    frequency : ndarray (F,)
        Frequencies [Hz], increasing, > 0.
    pairs : tuple of (output, input)
        The responses, e.g. ``("theta1", "tau1")``.
    values : ndarray (len(pairs), F), complex
        Output per input [SI unit per N m] at each frequency.
    """

    name: str
    source: str
    frequency: np.ndarray
    pairs: tuple[tuple[str, str], ...]
    values: np.ndarray


def read_frequency_response(path: str | Path) -> FrequencyResponse:
    """Read a frequency-response CSV (format in the module docstring).

    Parameters
    ----------
    path : path-like
        The CSV file: column ``f`` [Hz] and the real and imaginary parts of each
        output's response to a joint torque.

    Returns
    -------
    FrequencyResponse

    Raises
    ------
    ConfigError
        Naming the file and column of any defect.
    """
    path = Path(path)
    src = str(path)
    columns = _read_table(path)
    check("f" in columns, f"{src}: column f", "missing (frequency [Hz])")
    f = columns["f"]
    check(len(f) >= 1, f"{src}: column f", "no rows")
    check(bool(np.all(f > 0)), f"{src}: column f", "frequencies must be > 0 Hz")
    check(bool(np.all(np.diff(f) > 0)), f"{src}: column f", "frequencies must increase")
    pairs, values = [], []
    for col in columns:
        if col == "f":
            continue
        stem, dot, part = col.rpartition(".")
        out, slash, inp = stem.partition("/")
        check(bool(dot) and part in ("re", "im") and bool(slash) and bool(out) and bool(inp),
              f"{src}: column {col}", "expected OUTPUT/INPUT.re or OUTPUT/INPUT.im (e.g. "
                                      "theta1/tau1.re)")
        other = f"{stem}.{'im' if part == 're' else 're'}"
        check(other in columns, f"{src}: column {other}", f"missing (the other part of {col})")
        if part == "re":
            pairs.append((out, inp))
            values.append(columns[col] + 1j * columns[other])
    return FrequencyResponse(name=path.stem, source=src, frequency=f, pairs=tuple(pairs),
                             values=np.array(values))
