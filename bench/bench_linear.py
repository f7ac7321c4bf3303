"""Speed of the linear analysis: linear models of both plants, the ν-gap and the stability
margin, a case's predicted and certified control period (what `flexarm validity` spends
its time on).  Medians of REPEATS in this process (one BLAS thread, as the CLI).

No targets were set by an issue; the table says where the time of an analysis goes.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics  # noqa: E402
import time  # noqa: E402

import control  # noqa: E402
import numpy as np  # noqa: E402

from _report import report  # noqa: E402

REPEATS = 3


def timed(fn) -> float:
    samples = []
    for _ in range(REPEATS):
        t = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t)
    return statistics.median(samples)


def main():
    from controllers import PassivityBasedController
    from plant_exudyn import Mesh, linear_model
    from reduced_model import ArmModel, ArmParameters
    from validation import nu_gap, stability_margin
    from validation.run.scenario import scenario_from_mapping
    from validation.verdicts import sampled, stability
    from validation.verdicts.linear import law_gain, reduced_linear_model

    params, model = ArmParameters(), ArmModel(ArmParameters())
    names = list(model.state_names)
    x = np.zeros(12)
    x[1] = 0.5

    def hold(t):
        return x[:2].copy(), np.zeros(2), np.zeros(2)
    K = law_gain(PassivityBasedController(model, Ts=1e-3), x, 0.0, hold)
    gain = control.ss(np.zeros((0, 0)), np.zeros((0, 12)), np.zeros((2, 0)), K)
    red = control.sample_system(reduced_linear_model(model, theta=(0, 0.5))[names, :], 1e-3)
    fe = control.sample_system(linear_model(params, theta=(0, 0.5),
                                            model=model)[names, :], 1e-3)
    tf = control.tf

    def case(controller, plant):
        s = scenario_from_mapping({"controller": {"kind": controller}})
        (c,) = stability.cases_from_scenarios([s], plants=[plant], arms=["default"])
        return c.base

    def predict(config):
        sampled._prediction.cache_clear()
        sampled._case.cache_clear()
        return sampled.prediction(config)

    rows = [
        ("reduced model, StateSpace (12 states)", lambda: reduced_linear_model(model)),
        ("FE arm, StateSpace, ANCF 4+4 (72 states)", lambda: linear_model(params)),
        ("FE arm, StateSpace, ANCF 8+8 (136 states)",
         lambda: linear_model(params, Mesh(elements_per_link=(8, 8)))),
        ("PBC linearised from its object (12 states)",
         lambda: law_gain(PassivityBasedController(model, Ts=1e-3), x, 0.0, hold)),
        ("ν-gap, SISO (MATLAB example)",
         lambda: nu_gap(tf([1, 2], [1, 5, 10]), tf([1, 1], [1, 3, 10]))),
        ("ν-gap, PBC loop, reduced vs FE (12 + 72 states, ZOH)",
         lambda: nu_gap(gain * red, gain * fe)),
        ("b(P, C), PBC loop on the reduced model", lambda: stability_margin(gain * red, np.eye(2))),
        ("predicted Ts, PBC on the reduced plant (5 points)",
         lambda: predict(case("pbc", "reduced"))),
        ("predicted Ts, PBC on the FE arm (5 points)", lambda: predict(case("pbc", "exudyn"))),
        ("certificate of the PBC at one Ts (5 points)",
         lambda: sampled.certificate(case("pbc", "exudyn"), (1e-3,))),
    ]
    out = [{"analysis": name, "median_s": timed(fn)} for name, fn in rows]
    report("linear", out, title=f"Linear analysis (median of {REPEATS}, one BLAS thread)",
           columns=["analysis", "median_s"])


if __name__ == "__main__":
    main()
