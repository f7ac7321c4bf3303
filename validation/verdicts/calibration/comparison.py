"""Which model explains the data?  Calibrations of several models on the same data side by
side (``flexarm calibrate --compare``): residual, adequacy and information criteria in
one table, so that a user sees which effects their data need.

Fits are comparable only on the same data with the same weights: each calibration keeps
a fingerprint of both (`data_fingerprint`), and a fit is compared only with fits of the
same fingerprint.  With the weighted residual r (the noise levels as stated), a model of
p fitted parameters on m residuals scores

    AIC = rᵀr + 2p,        BIC = rᵀr + p ln m

(−2 ln L of Gaussian noise of the stated levels, up to a constant shared by every model
on the data: Akaike 1974; Schwarz 1978).  The lower the better; a difference of 10 is
decisive (Burnham & Anderson, *Model Selection and Multimodel Inference*, §2.6), and a
model that fails the residual tests is inadequate whatever its score: the score ranks
the models tried, the adequacy says whether any of them is enough.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from ...run.config import ConfigError, check
from ...run.plants import label_of
from ...run.results import read_json
from ...run.scenario import scenario_from_mapping
from .plan import Plan

__all__ = ["data_fingerprint", "model_description", "joint_effects", "comparison", "read_fits",
           "adequacy_words"]

#: What a compared calibration.json must hold (`read_json` checks it before it is read).
_SCHEMA = {"model_adequate?": (bool, type(None)), "cost": (int, float),
           "adequacy?": {"failing": [str], "noise_as_stated": (bool, type(None))},
           "model?": {"plant": str, "fitted": [str]},
           "data?": {"sha256": str, "residuals": int}}


def data_fingerprint(plan: Plan) -> dict:
    """The data a plan fits and their weights: ``sha256`` of every experiment's samples,
    torques and weights and every response's values, and ``residuals`` (m)."""
    digest = hashlib.sha256()
    residuals = 0
    for target in plan.targets:
        exp = target.experiment
        for array in (exp.torques, exp.signals, target.sigma):
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
        digest.update(",".join(exp.names).encode())
        residuals += exp.signals.size
    for response in plan.responses:
        digest.update(np.ascontiguousarray(response.frequency, dtype=np.float64).tobytes())
        digest.update(np.ascontiguousarray(response.values, dtype=np.complex128).tobytes())
        digest.update(repr((response.pairs, plan.settings.frf_noise)).encode())
        residuals += 2 * response.values.size
    return {"sha256": digest.hexdigest(), "residuals": residuals}


def joint_effects(arm, fitted=()) -> str:
    """The joint physics an arm has (or is fitted with) in words, without values:
    "joint 1: Coulomb+viscous friction, drive with backlash", or "ideal joints"."""
    def present(name):
        return getattr(arm, name) > 0 or name in fitted
    parts = []
    for i in range(1, arm.n_links + 1):
        friction = []
        if f"breakaway{i}" in fitted or \
                arm.joints[i - 1].static_friction > getattr(arm, f"coulomb{i}"):
            friction.append("Stribeck")
        elif present(f"coulomb{i}"):
            friction.append("Coulomb")
        if present(f"viscous{i}"):
            friction.append("viscous")
        items = ["+".join(friction) + " friction"] if friction else []
        if present(f"gear_stiffness{i}"):
            items.append("drive" + (" with backlash" if present(f"backlash{i}") else ""))
        if present(f"torque_time_constant{i}"):
            items.append("current loop")
        if items:
            parts.append(f"joint {i}: " + ", ".join(items))
    return "; ".join(parts) or "ideal joints"


def model_description(plan: Plan) -> dict:
    """The fitted model: its ``plant`` in words (label, discretisation or model order,
    kinematics, joint effects: what tells two models apart) and the ``fitted``
    parameters."""
    s = scenario_from_mapping(plan.base)
    spec = s.plant
    details = [spec.discretisation() or (
        "{}+{} modes".format(*spec.modes_per_link) if hasattr(spec, "modes_per_link") else "")]
    if hasattr(spec, "kinematics"):
        details.append(f"{spec.kinematics} kinematics")
    fitted = {p.name.partition(".")[2] for p in plan.settings.parameters}
    details.append(joint_effects(s.true_params, fitted))
    plant = ", ".join([label_of(plan.base), *(d for d in details if d)])
    return {"plant": plant, "fitted": [p.short for p in plan.settings.parameters]}


def read_fits(folders, data: dict) -> list[tuple[str, dict]]:
    """(folder, calibration.json) of each of ``folders``, checked to be calibrations of
    the same ``data`` (`data_fingerprint`): ConfigError naming ``--compare`` otherwise.
    Read before anything runs."""
    fits = []
    for folder in folders:
        path = Path(folder) / "calibration.json"
        check(path.is_file(), "--compare", f"{folder}: no calibration.json (not the folder of "
                                           "a flexarm calibrate)")
        try:
            fit = read_json(path, _SCHEMA)
        except ValueError as exc:
            raise ConfigError("--compare", str(exc)) from None
        check(all(k in fit for k in ("data", "model", "adequacy", "model_adequate")), "--compare",
              f"{path}: made by an older flexarm calibrate (no data fingerprint): run it again")
        check(fit["data"]["sha256"] == data["sha256"], "--compare",
              f"{path}: fitted other data or other noise levels (the same experiments, "
              "responses and weights are needed for a comparison)")
        fits.append((str(folder), fit))
    return fits


def adequacy_words(fit: dict) -> str:
    """A fit's adequacy in a table cell."""
    verdict = fit["adequacy"]
    if fit["model_adequate"] is None:
        return "not judged"
    if not fit["model_adequate"]:
        failing = len(verdict["failing"])
        return f"INADEQUATE ({failing} test{'s' if failing != 1 else ''} fail)"
    return "adequate" + ("" if verdict["noise_as_stated"] is not False else ", noise misstated")


def comparison(fits: list[tuple[str, dict]]) -> list[dict]:
    """One row per fit (folder, model), best AIC first: ``folder``, ``plant``,
    ``fitted``, ``p``, ``chi2`` (rᵀr), ``rms`` (√(rᵀr/m), in noise levels),
    ``adequacy``, ``aic``, ``bic``, ``delta_aic`` (from the best)."""
    rows = []
    for folder, fit in fits:
        m, p = fit["data"]["residuals"], len(fit["model"]["fitted"])
        chi2 = 2.0 * fit["cost"]
        rows.append({"folder": folder, "plant": fit["model"]["plant"],
                     "fitted": fit["model"]["fitted"], "p": p, "chi2": chi2,
                     "rms": math.sqrt(chi2 / m), "adequacy": adequacy_words(fit),
                     "model_adequate": fit["model_adequate"],
                     "aic": chi2 + 2 * p, "bic": chi2 + p * math.log(m)})
    rows.sort(key=lambda row: row["aic"])
    for row in rows:
        row["delta_aic"] = row["aic"] - rows[0]["aic"]
    return rows
