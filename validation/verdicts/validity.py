"""Is the reduced model (the paper's eq. 1–3, 2 assumed modes per link) good enough to
design a controller on?  Frequency responses of both plants, the ν-gap over θ2, and per
stability-map case the predicted, certified and measured largest stable control period.

Per arm (`arm_validity`, any number of joints N): on a θ2 grid (the other joints at 0; a
single link at its one pose), the reduced model (the scenario's kinematics) and the FE arm
linearised (`reduced_linear_model`, `plant_exudyn.linear_model`, the FE modes projected
on the reduced model's mode shapes), their frequency responses τ_i → θ_i and τ_i → tip
deflection of each flexible link, and δν of three views of the pair, N×N transfer
matrices and their tip rows: τ → θ (what the encoders see), τ → tip deflections of the
flexible links, and the loop of the scenario's controller broken at the plant input at its Ts
(what feedback with that law sees, `sampled`).  A view whose coprime factorisation
cannot be computed (`nugap.FactorisationError`: on Table 1's arm, which has no damping at
all, the undamped FE modes that two outputs barely see) is left empty, not guessed;
where it is computed there, δν = 1 — two undamped plants whose resonances differ are as
far apart as feedback can tell.

Per case (`case_rows`): the predicted period on the linearisation of the case's plant —
for the truth plant, on the case's mesh and on a mesh twice as fine, since a truth-plant
number is a fact about the arm only if it survives refinement (with no stator inertia,
Table 1's FE joint-2 mobility grows as elements³) — the certified period, and the
measured bracket of the stability map if one is stored.  Where the FE prediction lies
below the truth plant's measured bracket, the truth plant is run again at 0.97× and
1.05× the prediction with an integration step of Ts/200 (`STEP_CHECK`): the stability
map steps Exudyn at up to 1 ms, which under-resolves the FE modes above ~50 Hz that carry
part of the joint mobility, so that its measured limit can be a property of the step.
"""
from __future__ import annotations

import dataclasses
import math
import time

import control
import numpy as np

from reduced_model import ArmModel
from reduced_model.joints import nonlinear_joint_effects

from ..run.laws import build_controller
from ..run.plants import is_truth, truth_settings
from ..run.scenario import scenario_from_mapping
from .linear import law_gain, reduced_linear_model
from .nugap import as_statespace, gap_detail
from .resolution import UNDECIDED
from .sampled import POINTS, certificate, certified_period, prediction
from .stability import _label, _options_key, load_stability
from .validity_file import channels

__all__ = ["THETA2", "FREQUENCIES_HZ", "CERTIFY_PERIODS", "STEP_CHECK", "arm_validity",
           "case_rows", "validity_analysis"]

#: θ2 grid [rad] of the ν-gap map and the frequency responses.
THETA2 = tuple(float(t) for t in np.linspace(0.0, np.pi, 7))
#: Frequencies [Hz] of the frequency responses.
FREQUENCIES_HZ = tuple(float(f) for f in np.logspace(-1, np.log10(300.0), 400))
#: Control periods [s] at which the certificate is evaluated.
CERTIFY_PERIODS = (1e-4, 2e-4, 3e-4, 5e-4, 7e-4, 1e-3, 1.5e-3, 2e-3, 3e-3, 5e-3, 1e-2)
#: The truth plant rerun around an FE prediction: factors of the prediction, steps per Ts.
STEP_CHECK = ((0.97, 1.05), 200)


def arm_validity(config: dict) -> dict:
    """The frequency responses and ν-gaps over `THETA2` of the arm of ``config`` (a
    resolved scenario mapping: its true parameters, FE mesh, model order and Ts), as
    JSON-able data (module docstring)."""
    s = scenario_from_mapping(config)
    model = ArmModel(s.true_params, s.model.modes_per_link, s.model.kinematics)
    truth = truth_settings(config)
    names = list(model.state_names)
    N = model.n_joints
    w = 2 * np.pi * np.asarray(FREQUENCIES_HZ)
    law = build_controller(s, model)
    arm_channels = channels(model.modes_per_link)
    encoders = [f"motor{i + 1}" for i in range(N)]  # θ, or a drive's rotor: what they read
    tips = [o for _, o in arm_channels if o.startswith("tip_defl")]
    responses, gaps = [], []
    for theta2 in THETA2 if N > 1 else (0.0,):  # one link: its one pose
        theta = np.zeros(N)
        theta[1:2] = theta2
        red = reduced_linear_model(model, theta=tuple(theta))
        fe = truth.linear_model(s.true_params, theta=tuple(theta), model=model)
        entry = {"theta2": theta2}
        for label, P in (("reduced", red), ("fe", fe)):
            H = P(1j * w)  # (outputs, inputs, frequencies)
            entry[label] = {f"{i}->{o}": np.abs(H[P.output_labels.index(o),
                                                  P.input_labels.index(i)]).tolist()
                            for i, o in arm_channels}
        responses.append(entry)
        x = np.zeros(2 * model.n)
        x[:N] = theta  # the law holding the arm at rest at θ

        def hold(t, x=x):
            return x[:N].copy(), np.zeros(N), np.zeros(N)
        gain = as_statespace(law_gain(law, x, 0.0, hold, shared=(model,)))
        views = {"theta": (red[encoders, :], fe[encoders, :]),
                 "tip": (red[tips, :], fe[tips, :]),
                 "loop": (gain * control.sample_system(red[names, :], s.Ts),
                              gain * control.sample_system(fe[names, :], s.Ts))}
        row = {"theta2": theta2}
        for view, (a, b) in views.items():
            try:
                if not a.noutputs:  # a rigid arm: no tip deflects
                    raise ArithmeticError
                detail = gap_detail(a, b)
            except ArithmeticError:  # FactorisationError: shown as not computed
                row[view] = row[f"{view}_peak_hz"] = math.nan
                continue
            row[view], row[f"{view}_peak_hz"] = detail.value, detail.frequency / (2 * np.pi)
        gaps.append(row)
    return {"arm": s.arm, "Ts": s.Ts, "modes": list(s.model.modes_per_link),
            "law": s.controller.kind, "left_out": list(nonlinear_joint_effects(s.true_params)),
            "truth": _truth_text(config), "frequencies_hz": list(FREQUENCIES_HZ),
            "responses": responses, "gaps": gaps}


def _refined(config: dict) -> dict:
    """``config`` on its truth plant refined once (mesh and step)."""
    return dict(config, plant=truth_settings(config).refined(1))


def _truth_text(config: dict) -> str:
    """"truth plant (Exudyn), ANCF 4 el/link": the truth plant a case is set against."""
    spec = truth_settings(config)
    return ", ".join(x for x in (spec.label, spec.discretisation()) if x)


def _step_check(config: dict, period: float) -> str:
    """The truth plant at `STEP_CHECK` multiples of ``period`` with a fine step."""
    from ..run.loop import run_scenario
    factors, steps = STEP_CHECK
    out = []
    for f in factors:
        Ts = f * period
        data = dict(config, Ts=Ts, plant=dict(config["plant"], step=Ts / steps))
        result = run_scenario(scenario_from_mapping(data))
        out.append(f"{f:g}×: {result.status}")
    return f"truth plant with step Ts/{steps}: " + ", ".join(out)


def case_rows(cases, stability=(), *, progress=None) -> list[dict]:
    """One row per stability-map case (module docstring); ``stability`` holds the
    measured `StabilityResult` of the cases, matched by case."""
    measured = {(_label(r.case.base), _options_key(r.case.base), r.case.plant, r.case.arm): r
                for r in stability}
    certificates: dict = {}
    rows = []
    for case in cases:
        base = case.base
        started = time.perf_counter()
        own = prediction(base)
        row = {"case": case.label, "plant": case.plant, "arm": case.arm,
               "predicted_s": own.period, "predicted_theta2": own.theta2,
               "note": own.note, "mesh": "", "predicted_fine_s": math.nan, "mesh_fine": "",
               "truth": is_truth(base)}
        if is_truth(base):
            row["mesh"], row["mesh_fine"] = _truth_text(base), _truth_text(_refined(base))
            row["predicted_fine_s"] = prediction(_refined(base)).period
        key = (_options_key(base), case.arm, _truth_text(base))
        if key not in certificates:
            cert = certificate(base, CERTIFY_PERIODS)
            certificates[key] = (certified_period(cert), cert)
        row["certified_s"], cert = certificates[key]
        row["certificate"] = [dataclasses.asdict(c) for c in cert]
        result = measured.get((case.label, _options_key(base), case.plant, case.arm))
        row.update(_against_measured(row, result, base))
        row["seconds"] = time.perf_counter() - started
        rows.append(row)
        if progress:
            progress(row)
    return rows


def _against_measured(row: dict, result, base: dict) -> dict:
    """The measured bracket and where the limit lies (the bracket with its error and the
    outcome test's band: `ResolvedLimit.interval`), whether the prediction lies there, the
    soundness and the conservatism of the certificate, and the fine-step check of the
    truth plant."""
    out = {"largest_stable_s": math.nan, "first_unstable_s": math.nan, "in_bracket": "",
           "limit_low_s": math.nan, "limit_high_s": math.nan, "limit_verdict": "",
           "sound": "", "conservatism": math.nan, "evidence": ""}  # why a prediction
    # misses its bracket, as measured
    if result is None:
        return out
    # A linear stability prediction is about divergence: it is set against the map's
    # no-divergence limit (a loss of tracking is not an instability).
    lo, hi = result.divergence.largest, result.divergence.first_bad
    resolved = result.resolved["divergence"]
    low, high = resolved.interval()
    out |= {"largest_stable_s": lo, "first_unstable_s": hi, "limit_low_s": low,
            "limit_high_s": high, "limit_verdict": resolved.verdict or "n/a"}
    p = row["predicted_s"]
    if not math.isnan(p):
        out["in_bracket"] = "not converged" if math.isnan(low) else \
            "yes" if low <= p < high else "no"
        if out["in_bracket"] == "no" and result.divergence.outcome == "failed":
            out["evidence"] = ("the measured bracket ends at a solver failure, not a "
                               "divergence: it says nothing about the limit")
    c = row["certified_s"]
    if row["truth"] and c == 0:
        out["sound"], out["conservatism"] = "nothing certified", 0.0
    elif row["truth"] and not math.isnan(c):
        unstable = [Ts for Ts, (o, _) in result.tested.items() if Ts <= c and o == "diverged"]
        # Sound: the limit lies above the certified period; where the certified period
        # is inside the limit's resolution, neither (the one rule of `resolution`).
        out["sound"] = f"NO: unstable at {min(unstable):g} s" if unstable else \
            "yes" if c <= low or math.isnan(low) and c < lo else UNDECIDED
        if lo > 0:
            out["conservatism"] = c / lo
    if (row["truth"] and base["observer"]["kind"] == "none"
            and math.isfinite(p) and p >= min(result.tested) and not math.isnan(lo) and p < lo):
        out["evidence"] = _step_check(base, p)
    return out


def validity_analysis(cases, *, stability_dir=None, progress=None) -> dict:
    """The whole analysis of `flexarm validity` as JSON-able data: per arm of ``cases``
    (`arm_validity`), per case (`case_rows`), the timings."""
    timings = {}
    stability = []
    if stability_dir is not None:  # runs made by other code are stale: left out
        stability = load_stability(stability_dir, fresh_only=True)
    arms = {}
    for case in cases:  # an FE case carries the mesh; any case carries the arm
        if case.arm not in arms or case.truth:
            arms[case.arm] = case.base
    started = time.perf_counter()
    per_arm = [arm_validity(config) for config in arms.values()]
    timings["frequency responses and ν-gap over θ2 [s]"] = time.perf_counter() - started
    started = time.perf_counter()
    rows = case_rows(cases, stability, progress=progress)
    timings["predictions, certificates and checks [s]"] = time.perf_counter() - started
    return {"arms": per_arm, "cases": rows, "timings": timings,
            "stability": str(stability_dir) if stability_dir else "",
            "certify_periods": list(CERTIFY_PERIODS), "points": POINTS}
