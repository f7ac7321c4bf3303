"""What a calibration writes into its results folder: the experiments as read and
the torques replayed, ``calibration.json``, ``calibrated.toml`` and ``uncertainty.toml``."""
from __future__ import annotations

import copy
import hashlib
import io
import json
from pathlib import Path

import numpy as np

from ...run.experiments import write_experiment
from ...run.results import LinkedFolder, own_folder, write_atomic
from ...run.tomlfiles import set_dotted, toml_text, toml_value
from .plan import Plan

__all__ = ["refuse_links", "write_inputs", "write_results", "RESULT_FILES",
           "CALIBRATION_VERDICTS", "EXTENDED"]


#: The files a calibration writes at the top of its results folder.
RESULT_FILES = ("calibration.json", "calibrated.toml", "uncertainty.toml")
#: The folder of the fit of the extended model that makes an inadequate one adequate.
EXTENDED = "extended"


def refuse_links(plan: Plan, out) -> None:
    """`LinkedFolder` (one line naming the path) if anything the calibration would write
    in ``out`` — ``experiments/`` and its files, the result files — is a symbolic link or
    is not what it should be: nothing is written through a link out of the folder the
    user chose (``out`` itself may be one).  Checked before anything is written."""
    out = Path(out)
    folder = out / "experiments"
    files = [out / name for name in RESULT_FILES]
    files += [out / EXTENDED / name for name in RESULT_FILES]
    files += [folder / f"{t.experiment.name}{suffix}" for t in plan.targets
              for suffix in (".csv", ".npy")]
    for sub in (folder, out / EXTENDED):
        if sub.is_symlink() or (sub.exists() and not sub.is_dir()):
            own_folder(out, sub.name)  # raises, naming it
    for path in files:
        if path.is_symlink() or path.is_dir():
            raise LinkedFolder(f"{path}: a {'symbolic link' if path.is_symlink() else 'folder'}"
                               " where the calibration writes a file of its own; nothing is "
                               "written through it")


def write_inputs(plan: Plan, out: Path) -> list[dict]:
    """Write each experiment as read (``experiments/NAME.csv``: what the report compares
    with) and, for replay, its torques (``.npy``); the scenario keys that reproduce each
    experiment's input."""
    refuse_links(plan, out)
    out.mkdir(parents=True, exist_ok=True)
    # absolute (the workers read the torques by path), the folder's own links refused
    folder = own_folder(out, "experiments").resolve() if plan.targets else None
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
        path = folder / f"{exp.name}.npy"
        write_atomic(path, lambda fh, d=data: fh.write(d), binary=True)
        inputs.append({
            "controller": {"kind": "replay", "options": {
                "file": str(path), "sha256": hashlib.sha256(data).hexdigest()}},
            "observer": {"kind": "none", "options": {}, "initial_error": []},
            "feedback": "true", "disturbances": [], "torque_limit": 0.0, "requirement": [],
            "sensors": {"encoder_noise": 0.0, "modal_noise": 0.0, "rate_noise": 0.0}})
    return inputs



#: What ``uncertainty.toml`` says, in ``[verify] calibration``, of the model it came
#: from (`validation.verdicts.uncertainty` carries it onto every verdict).
CALIBRATION_VERDICTS = {True: "adequate", False: "inadequate", None: "not judged"}


def _calibrated(out: Path, plan: Plan, result: dict, advice: str) -> None:
    calibrated = copy.deepcopy(plan.base)
    for name, p in result["parameters"].items():
        set_dotted(calibrated, name, p["estimate"])
    effective = result["model_adequate"] is not True
    lines = [f"{n} = {p['estimate']:.6g}" + (
        " (not identifiable)" if not p["identifiable"] else
        f" (effective, {p['interval'][0]:.6g}..{p['interval'][1]:.6g})" if effective else
        f" ± {p['std']:.2g}") for n, p in result["parameters"].items()]
    head = ("The scenario calibrated by flexarm calibrate (calibration.json): "
            + "; ".join(lines) + f"\nThe model: {result['adequacy']['verdict']}\n" + advice)
    text = "".join(f"# {ln}\n" for ln in head.splitlines()) + toml_text(calibrated)
    write_atomic(out / "calibrated.toml", lambda fh: fh.write(text))


def _uncertainty(out: Path, plan: Plan, result: dict) -> None:
    """``uncertainty.toml``: each identifiable parameter uniform over its interval, with
    the verdict on the model (removed when none is identifiable or it is not exported)."""
    effective = result["model_adequate"] is not True
    ranges = {}
    for (name, p), q in zip(result["parameters"].items(), plan.settings.parameters):
        if p["identifiable"]:
            ranges[name] = (max(p["interval"][0], q.lower), min(p["interval"][1], q.upper))
    path = out / "uncertainty.toml"
    if not ranges or not result.get("exported", True):
        path.unlink(missing_ok=True)
        return
    verdict = CALIBRATION_VERDICTS[result["model_adequate"]]
    what = ("95 % intervals" if not effective else
            "intervals of EFFECTIVE parameters of a model the residual tests call "
            f"{verdict.upper()} — not 95 % intervals of the physical arm —")
    warning = ("# WARNING: written by --export-inadequate: these ranges may exclude the arm's\n"
               "# true values (the model misses physics; see calibration.json: extensions).\n"
               if result["model_adequate"] is False else "")
    text = (f"# The calibrated arm's {what} (flexarm calibrate, calibration.json) as the\n"
            "# set flexarm verify draws from: each uniform over its interval, independently\n"
            "# (correlations are in calibration.json).  Include it next to calibrated.toml;\n"
            "# flexarm verify states [verify] calibration on its verdicts.\n" + warning +
            "[uncertainty]\n" + "".join(f'"{n}" = {{ uniform = {toml_value([lo, hi])} }}\n'
                                        for n, (lo, hi) in ranges.items())
            + f'[verify]\ncalibration = "{verdict}"\n')
    write_atomic(path, lambda fh: fh.write(text))


def write_results(out: Path, plan: Plan, result: dict, extended=None) -> None:
    """``calibration.json`` (``result``), ``calibrated.toml`` (the base scenario with the
    estimates) and ``uncertainty.toml`` (each identifiable parameter uniform over its
    interval, with the verdict on the model; not for an inadequate model unless
    ``result["exported"]``); with ``extended`` = (plan, result) of the extended model that
    is adequate, the same three of it in `EXTENDED`/ (an earlier one removed otherwise)."""
    write_atomic(out / "calibration.json",
                 lambda fh: json.dump(result, fh, indent=1, allow_nan=False))
    _calibrated(out, plan, result, "Run it: flexarm run --config calibrated.toml\n")
    _uncertainty(out, plan, result)
    folder = out / EXTENDED
    if extended is None:
        for name in RESULT_FILES:
            (folder / name).unlink(missing_ok=True)
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        return
    folder = own_folder(out, EXTENDED)
    wider, fit = extended
    write_atomic(folder / "calibration.json",
                 lambda fh: json.dump(fit, fh, indent=1, allow_nan=False))
    _calibrated(folder, wider, fit, "Run it: flexarm run --config calibrated.toml (the "
                                    "model extended by flexarm calibrate)\n")
    _uncertainty(folder, wider, fit)
