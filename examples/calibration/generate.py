"""Make this folder's synthetic experiments: the toolkit's truth plant at stated
parameters, with the campaigns' sensor noise.  Run from the repository root:

    .venv/bin/python examples/calibration/generate.py

SYNTHETIC DATA: no arm was measured.  The "true" arm is the default arm with EI1 = 9.2,
EI2 = 10.6 N m² and a 0.23 kg payload (what arm.toml's owner does not know); noise
1e-4 rad on the angles and 1e-5 on the strain-derived modal coordinates (seeds 1, 2,
3); each file keeps 2 s at 1 kHz of theta1, theta2, q11, q21 (7 significant digits).

reversals.csv is of a second synthetic arm, the same links behind a joint 1 with
friction (Coulomb 0.25 N m, viscous 0.15 N m s/rad: what friction.toml's owner does not
know), tracking a reference designed to identify it: sines of 0.2 rad at 0.5 and
0.65 Hz, whose velocities pass through zero at 0.5 and 1.5 s (joint 1) — a reversal
shows the Coulomb level as a jump of the friction torque, where a motion in one
direction would show it only as a constant offset of the torque (seed 4).
"""
from pathlib import Path

import numpy as np

from validation import run_scenario, scenario_from_mapping
from validation.run.experiments import Experiment, from_run, write_experiment
from validation.verdicts.calibration import linear_response

HERE = Path(__file__).resolve().parent
TRUE = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23}
FRICTION = {"coulomb1": 0.25, "viscous1": 0.15}
#: Velocity reversals: sines slow against the arm's first free mode (2.2 Hz), large
#: enough to slip the joint through its friction, small enough to stay in the linear
#: range of the links (0.5 rad at these frequencies bent link 1 beyond half its length).
REVERSALS = {"kind": "paper", "amplitude": [0.2, 0.2], "omega": [np.pi, 1.3 * np.pi]}
NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
KEPT = ("theta1", "theta2", "q11", "q21")
LABEL = ("SYNTHETIC experiment made by examples/calibration/generate.py (no arm was "
         "measured):\nthe truth plant with EI1 = 9.2, EI2 = 10.6 N m^2, Mp = 0.23 kg{joint}, "
         "the PBC tracking {reference},\nnoise 1e-4 rad, 1e-5 m (seed {seed}); {start}.")


def experiment(name: str, seed: int, initial_state: str, friction: bool = False) -> None:
    scenario = scenario_from_mapping({
        "duration": 2.0, "plant": {"kind": "exudyn"}, "seed": seed, "sensors": NOISE,
        "true_params": {**TRUE, **(FRICTION if friction else {})},
        "initial_state": initial_state, **({"reference": REVERSALS} if friction else {})})
    full = from_run(run_scenario(scenario), name, name)
    rows = [full.names.index(n) for n in KEPT]
    kept = Experiment(name, name, full.Ts, full.torques, KEPT, full.signals[rows])
    start = "from rest" if initial_state == "rest" else "starting moving with the reference"
    label = LABEL.format(
        seed=seed, start=start,
        joint=",\njoint 1 friction coulomb1 = 0.25 N m, viscous1 = 0.15 N m s/rad" if friction
        else "", reference="0.2 sin(pi t), 0.2 sin(1.3 pi t) (velocity reversals)" if friction
        else "eq. (37)")
    with (HERE / f"{name}.csv").open("w") as fh:
        write_experiment(kept, fh, label, digits=7)


def frequency_response(seed: int) -> None:
    """A modal test's responses at rest (0.5-40 Hz), each with 1 % complex noise."""
    scenario = scenario_from_mapping({"plant": {"kind": "exudyn"}, "true_params": TRUE})
    f = np.geomspace(0.5, 40.0, 40)
    pairs = (("theta1", "tau1"), ("theta2", "tau2"), ("q11", "tau1"), ("q21", "tau2"))
    G = linear_response(scenario, (0.0, 0.0), f, pairs)
    rng = np.random.default_rng(seed)
    G = G * (1 + 0.01 * (rng.standard_normal(G.shape) + 1j * rng.standard_normal(G.shape)))
    columns = [f"{o}/{i}.{part}" for o, i in pairs for part in ("re", "im")]
    with (HERE / "frf.csv").open("w") as fh:
        fh.write("# SYNTHETIC frequency response made by examples/calibration/generate.py: "
                 "the truth plant\n# linearised at rest (EI1 = 9.2, EI2 = 10.6, Mp = 0.23), "
                 f"1 % complex noise (seed {seed})\n")
        fh.write(",".join(["f", *columns]) + "\n")
        for j, fj in enumerate(f):
            values = [x for g in G[:, j] for x in (g.real, g.imag)]
            fh.write(",".join(f"{v:.7g}" for v in [fj, *values]) + "\n")


if __name__ == "__main__":
    experiment("tracking", 1, "rest")
    experiment("moving", 2, "reference")
    experiment("reversals", 4, "rest", friction=True)
    frequency_response(3)
