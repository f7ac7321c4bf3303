"""What a calibration writes into its results folder: the experiments as read and
the torques replayed, ``calibration.json``, ``calibrated.toml`` and ``uncertainty.toml``."""
from __future__ import annotations

import copy
import hashlib
import io
import json
from pathlib import Path

import numpy as np

from ..run.experiments import write_experiment
from ..run.results import write_atomic
from ..run.tomlfiles import set_dotted, toml_text, toml_value
from .calibration_plan import Plan

__all__ = ["write_inputs", "write_results"]


def write_inputs(plan: Plan, out: Path) -> list[dict]:
    """Write each experiment as read (``experiments/NAME.csv``: what the report compares
    with) and, for replay, its torques (``.npy``); the scenario keys that reproduce each
    experiment's input."""
    folder = out / "experiments"
    out.mkdir(parents=True, exist_ok=True)
    if plan.targets:
        folder.mkdir(exist_ok=True)
    inputs = []
    for target in plan.targets:
        exp = target.experiment
        write_atomic(folder / f"{exp.name}.csv", lambda fh, e=exp: write_experiment(
            e, fh, f"experiment {e.name}, read from {e.source}"))
        if plan.settings.inputs == "closed-loop":
            inputs.append({})
            continue
        buffer = io.BytesIO()
        np.save(buffer, np.ascontiguousarray(exp.torques, dtype=np.float64), allow_pickle=False)
        data = buffer.getvalue()
        path = (folder / f"{exp.name}.npy").resolve()
        write_atomic(path, lambda fh, d=data: fh.write(d), binary=True)
        inputs.append({
            "controller": {"kind": "replay", "options": {
                "file": str(path), "sha256": hashlib.sha256(data).hexdigest()}},
            "observer": {"kind": "none", "options": {}, "initial_error": []},
            "feedback": "true", "disturbances": [], "torque_limit": 0.0, "requirement": [],
            "sensors": {"encoder_noise": 0.0, "modal_noise": 0.0, "rate_noise": 0.0}})
    return inputs



def write_results(out: Path, plan: Plan, result: dict) -> None:
    write_atomic(out / "calibration.json",
                 lambda fh: json.dump(result, fh, indent=1, allow_nan=False))
    calibrated = copy.deepcopy(plan.base)
    for name, p in result["parameters"].items():
        set_dotted(calibrated, name, p["estimate"])
    lines = [f"{n} = {p['estimate']:.6g}" + (f" ± {p['std']:.2g}" if p["identifiable"]
                                             else " (not identifiable)")
             for n, p in result["parameters"].items()]
    head = ("The scenario calibrated by flexarm calibrate (calibration.json): "
            + "; ".join(lines) + "\nRun it: flexarm run --config calibrated.toml\n")
    text = "".join(f"# {ln}\n" for ln in head.splitlines()) + toml_text(calibrated)
    write_atomic(out / "calibrated.toml", lambda fh: fh.write(text))
    ranges = {}
    for (name, p), q in zip(result["parameters"].items(), plan.settings.parameters):
        if p["identifiable"]:
            lo, hi = max(p["ci95"][0], q.lower), min(p["ci95"][1], q.upper)
            ranges[name] = (lo, hi)
    path = out / "uncertainty.toml"
    if not ranges:
        path.unlink(missing_ok=True)
        return
    text = ("# The calibrated arm's 95 % intervals (flexarm calibrate, calibration.json) as the\n"
            "# set flexarm verify draws from: each uniform over its interval, independently\n"
            "# (correlations are in calibration.json).  Include it next to calibrated.toml.\n"
            "[uncertainty]\n" + "".join(f'"{n}" = {{ uniform = {toml_value([lo, hi])} }}\n'
                                        for n, (lo, hi) in ranges.items()))
    write_atomic(path, lambda fh: fh.write(text))
