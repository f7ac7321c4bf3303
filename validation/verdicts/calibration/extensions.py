"""Which physics does an inadequate model lack?  The toolkit's joint and kinematic effects
tried as extensions of the user's model, screened, fitted and ranked (``flexarm
calibrate``).

A model the residual tests call inadequate has effective parameters, not physical ones,
and nothing in its residual names what it misses.  The toolkit has the physics an arm's
model commonly lacks; each one the model does not have already is a *candidate*
extension (`candidates`):

* joint friction (Coulomb and viscous), where a joint has none;
* a Stribeck effect (a breakaway above the Coulomb level), where a joint has friction;
* a drive (gear compliance, its damping and a rotor's inertia), with and without
  backlash, where a joint has none; backlash, where a joint has a drive without it;
* exact kinematics, for the reduced plant with the paper's linear kinematics.

**The screen** asks of each candidate, at a few values of its parameters (`Extension.
probes`), how much of the residual the change it makes to the outputs could explain:
with d the change of the residual (one simulation at the estimate with the probe's
values) and W the noise models' whitening (`validation.verdicts.calibration.noise`), the
reduction of the whitened cost when the residual may move along d (with a non-negative
weight) besides the fitted parameters' own directions J,

    Δ = (gᵀe)² / gᵀg   where e, g = (I − P_WJ) W r, (I − P_WJ) W d   (0 if gᵀe > 0),

a score statistic: χ²(1) when the model is right and its residual is the modelled
noise.  The largest Δ over a candidate's probes is its score (a probe whose simulation
failed is no evidence and is left out; a candidate with none left is not screened); a
score beyond the χ²(1) quantile at `FAMILY_ALPHA` over the number of probes is
*significant*.  A residual the
tests found correlated but at the stated level and independent of the inputs — coloured
noise, or a mild model error — is called coloured noise only if no candidate is
significant (`validation.verdicts.calibration.adequacy`).

**The search** (`validation.verdicts.calibration.workflow`) fits the significant
candidates as extensions of the user's model, most significant first, until one is
adequate or `FITTED` have been tried: their new parameters from the best probe's values,
the others from the estimate (`fit_plan` with the horizon growing again).  A drive with
backlash is fitted after the drive alone, from that fit: from the probes' values its fit
found another minimum (the reduced plant with an unmodelled drive of 3e3 N m/rad, rotor
0.05 kg m², backlash 2e-4 rad: backlash 0, damping 47), where the drive alone came to
2850 N m/rad, 0.046 kg m².  Each is judged with the same tests and the tried ones ranked
by AIC; the verdict names the adequate one, or says that none of those tried makes the
model adequate.  A fit reaches only the minimum of the piece of the cost its start lies
on: where a velocity reversal's stick moves by a whole internal step, the outputs after
it jump, and a descent does not cross the jump.  A Stribeck effect far from the probes'
values is then fitted to an inadequate minimum (measured on the reduced plant, 2 s with
velocity reversals, Coulomb level 0.25: a breakaway of 0.4, 1.6 times it, fitted as
0.343 from the probe 0.353; a breakaway of 0.375 with a Stribeck velocity of 0.005 or
0.02 rad/s, fitted as 0.0099 and 0.0106 from the probes' 0.01).
"""
from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from ...run.config import ConfigError
from ...run.scenario import scenario_from_mapping
from ...run.tomlfiles import set_dotted
from .adequacy import FAMILY_ALPHA
from .joints import TYPICAL
from .plan import Plan
from .settings import Parameter

__all__ = ["Extension", "candidates", "extended", "score", "screen", "FITTED"]

#: The most candidates fitted after the screen.
FITTED = 3
#: A drive's stiffness [N m/rad] and backlash [rad] at the screen's probes: the typical
#: range of a small harmonic drive (docs/theory/joints.rst, *Typical values*).
_STIFFNESSES = (1e3, 3e3, 1e4, 3e4)
_BACKLASHES = (1e-4, 3e-4)


@dataclass(frozen=True)
class Extension:
    """A candidate extension: its ``name`` in words, the scenario keys it sets (dotted)
    at its start, the new fields it fits, the points of its screen, and the candidate it
    builds on (a drive with backlash on the drive: fitted from that one's fit)."""

    name: str
    changes: dict
    fitted: tuple[str, ...]
    probes: tuple[dict, ...]
    builds_on: str = ""


def _tp(field: str, i: int) -> str:
    return f"true_params.{field}{i}"


def _drive(i: int, stiffness: float) -> dict:
    rotor, damping = TYPICAL["rotor_inertia"][1], TYPICAL["gear_damping"][1]
    return {_tp("gear_stiffness", i): stiffness, _tp("rotor_inertia", i): rotor,
            _tp("gear_damping", i): damping}


def candidates(plan: Plan, estimate: dict) -> list[Extension]:
    """The extensions the plan's model does not have (module docstring), each one an arm
    the scenario accepts at the ``estimate`` (fitted name → value)."""
    at = _changed(plan.base, estimate)
    arm, fitted = scenario_from_mapping(at).true_params, set(plan.settings.names)
    has = lambda field, i: getattr(arm, f"{field}{i}") > 0 or _tp(field, i) in fitted  # noqa: E731
    out = []
    for i in range(1, arm.n_links + 1):
        friction = has("coulomb", i) or has("viscous", i)
        if not friction:
            start = {_tp("coulomb", i): TYPICAL["coulomb"][1],
                     _tp("viscous", i): TYPICAL["viscous"][1]}
            out.append(Extension(f"joint {i} Coulomb+viscous friction", start, tuple(start),
                                 ({_tp("coulomb", i): 0.1, _tp("viscous", i): 0.05}, start)))
        if _tp("breakaway", i) not in fitted and \
                arm.joints[i - 1].static_friction <= getattr(arm, f"coulomb{i}"):
            coulomb = getattr(arm, f"coulomb{i}") if has("coulomb", i) else \
                TYPICAL["coulomb"][1]
            own = {} if friction else {_tp("coulomb", i): coulomb,
                                       _tp("viscous", i): TYPICAL["viscous"][1]}
            velocity = TYPICAL["stribeck_velocity"][1]
            probes = tuple({**own, _tp("breakaway", i): ratio * coulomb,
                            _tp("stribeck_velocity", i): velocity} for ratio in (1.1, 1.4))
            out.append(Extension(f"joint {i} Stribeck friction", probes[1],
                                 tuple(probes[1]), probes))
        if not has("gear_stiffness", i):
            start = _drive(i, TYPICAL["gear_stiffness"][1])
            out.append(Extension(f"joint {i} drive", start, tuple(start),
                                 tuple(_drive(i, k) for k in _STIFFNESSES)))
        if not has("backlash", i):
            drive = {} if has("gear_stiffness", i) else _drive(i, TYPICAL["gear_stiffness"][1])
            start = {**drive, _tp("backlash", i): TYPICAL["backlash"][1]}
            probes = tuple({**(_drive(i, k) if drive else {}), _tp("backlash", i): b}
                           for k in (_STIFFNESSES[1:3] if drive else (None,))
                           for b in _BACKLASHES)
            out.append(Extension(f"joint {i} {'drive with ' if drive else ''}backlash",
                                 start, tuple(start), probes,
                                 f"joint {i} drive" if drive else ""))
    if plan.base["plant"].get("kinematics") == "linear":
        exact = {"plant.kinematics": "exact"}
        out.append(Extension("exact kinematics", exact, (), (exact,)))
    return [e for e in out if _is_arm(at, e)]


def _is_arm(mapping: dict, extension: Extension) -> bool:
    """Whether every probe and the start of ``extension`` are arms the scenario accepts
    (joint 2's friction needs a stator inertia, say)."""
    for changes in (extension.changes, *extension.probes):
        try:
            scenario_from_mapping(_changed(mapping, changes))
        except ConfigError:
            return False
    return True


def _changed(mapping: dict, changes: dict) -> dict:
    """A copy of a scenario mapping with the dotted keys ``changes`` set."""
    data = copy.deepcopy(mapping)
    for key, value in changes.items():
        set_dotted(data, key, value)
    return data


def extended(plan: Plan, extension: Extension, changes: dict | None = None,
             fit: bool = True, start: dict | None = None) -> Plan:
    """The plan of ``plan``'s model with ``extension`` at ``changes`` (its start by
    default), its fitted fields starting from ``start`` (fitted name → value; default:
    their starts); with ``fit``, the extension's new fields fitted too (starts: their
    values in ``changes``; bounds: the typical ones, `joints.TYPICAL`)."""
    changes = {**(start or {}), **(extension.changes if changes is None else changes)}
    targets = tuple(dataclasses.replace(t, scenario=_changed(t.scenario, changes))
                    for t in plan.targets)
    settings = dataclasses.replace(plan.settings, parameters=tuple(
        dataclasses.replace(q, start=float(start[q.name])) if start and q.name in start
        else q for q in plan.settings.parameters))
    if fit and extension.fitted:
        new = []
        for name in extension.fitted:
            field = name.partition(".")[2]
            lower, upper = TYPICAL[field[:-1]][2]
            start = float(changes[name])
            new.append(Parameter(name, start, min(lower, start), max(upper, start),
                                 start if start > 0 else upper - lower))
        settings = dataclasses.replace(settings, parameters=settings.parameters + tuple(new))
    return Plan(settings, _changed(plan.base, changes), targets, plan.responses)


def _whitened(x: np.ndarray, rows, models) -> np.ndarray:
    """W x: each signal's part whitened by its noise model, in units of its innovations."""
    return np.concatenate([m.whiten(x[at]) / math.sqrt(m.innovation)
                           for at, m in zip(rows, models)])


def score(r: np.ndarray, J: np.ndarray, d: np.ndarray, rows, models) -> float:
    """Δ of the module docstring: the whitened cost a non-negative move along ``d`` saves
    beside J's columns."""
    e, WJ, g = (_whitened(x, rows, models) for x in (r, J, d))
    Q, S, _ = np.linalg.svd(WJ, full_matrices=False)
    Q = Q[:, S > 1e-12 * (S[0] if S.size else 1.0)]
    e = e - Q @ (Q.T @ e)
    g = g - Q @ (Q.T @ g)
    gg = float(g @ g)
    if gg <= 0.0:
        return 0.0
    ge = float(g @ e)
    return ge * ge / gg if ge < 0 else 0.0


def screen(plan: Plan, residuals_of, u: np.ndarray, r: np.ndarray, J: np.ndarray,
           rows, models) -> list[dict]:
    """Each candidate's score and the probe that gave it, most significant first (module
    docstring).

    Parameters
    ----------
    plan : Plan
        The fitted model's plan.
    residuals_of : callable
        [(plan, u)] → their residual vectors (one batch).
    u, r, J : ndarray
        The estimate (units of the scales), its residual and Jacobian.
    rows, models : list
        Each signal's rows in r and its noise model.
    """
    estimate = {q.name: float(x) for q, x in zip(plan.settings.parameters,
                                                 u * np.array([q.scale for q in
                                                               plan.settings.parameters]))}
    found = candidates(plan, estimate)
    probes = [(e, p) for e in found for p in e.probes]
    if not probes:
        return []
    values = residuals_of([(extended(plan, e, p, fit=False), u) for e, p in probes])
    threshold = float(scipy.stats.chi2.ppf(1 - FAMILY_ALPHA / len(probes), 1))
    best: dict[str, dict] = {}
    for (extension, probe), value in zip(probes, values):
        if not np.isfinite(value).all():
            continue  # its simulation failed: no evidence for or against the candidate
        delta = score(r, J, value - r, rows, models)
        if extension.name not in best or delta > best[extension.name]["score"]:
            best[extension.name] = {"name": extension.name, "score": delta, "probe": probe,
                                    "threshold": threshold,
                                    "significant": bool(delta > threshold)}
    return sorted(best.values(), key=lambda row: -row["score"])


