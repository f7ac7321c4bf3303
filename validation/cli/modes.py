"""``flexarm modes``: natural frequencies of the reduced model, the FE model and an
independent reference."""
from __future__ import annotations

import argparse

import numpy as np

from ..run.scenario import ARMS
from ..run.tomlfiles import load_toml


#: Independent reference frequencies [Hz] of Table 1's arm at θ1 = θ2 = 0: a converged
#: Euler–Bernoulli finite-element model built outside this code (the paper publishes
#: none).  Joints free: the two rigid modes left out.
TABLE1_REFERENCE_HZ = {"locked": (0.6316, 3.8312, 6.3499, 33.665),
                       "free": (2.2359, 6.1233, 31.414, 34.302)}


def _gap_percent(ours, reference) -> np.ndarray:
    """100 (ours − reference)/reference, rounded to the printed 4 decimals with no −0."""
    return np.round(100 * (np.asarray(ours) - reference) / reference, 4) + 0.0


def cmd_modes(args: argparse.Namespace) -> int:
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel, ArmParameters, validate_modes_per_link
    if args.params and args.table1:
        raise ValueError("--params and --table1 exclude each other")
    if args.table1:
        params, source = ArmParameters.table1(), ARMS["table1"]
    elif args.params:
        data = load_toml(args.params)
        if set(data) == {"params"} and isinstance(data["params"], dict):
            data = data["params"]
        params = ArmParameters.from_mapping(data, where=f"{args.params}:params")
        source = args.params
    else:
        params, source = ArmParameters(), ARMS["default"]
    model = ArmModel(params, validate_modes_per_link(args.modes_per_link, where="--modes-per-link"))
    mesh = Mesh(element=args.element, elements_per_link=args.elements) if args.compare else None
    n1, n2 = model.modes_per_link
    row = lambda label, values: f"  {label:<30}" + "".join(f"{v:>11.4f}" for v in values)  # noqa: E731
    print(f"Reduced model, {n1}+{n2} clamped-mass modes, arm: {source}")
    print("Clamped-mass link frequencies [Hz]")
    for i, modes in enumerate(model.mode_shapes, start=1):
        print(row(f"link {i}", modes.frequencies_hz))
    referenced = False
    for theta2 in args.theta2:
        Q = np.zeros(model.n)
        Q[1] = theta2
        print(f"Coupled frequencies at theta1 = 0, theta2 = {theta2:g} rad [Hz]")
        for joints in ("locked", "free"):
            reduced = model.natural_frequencies(Q, joints)
            label = "joints locked" if joints == "locked" else "joints free (non-zero)"
            print(row(label + (" reduced" if mesh else ""), reduced))
            if mesh:
                fe = natural_frequencies(params, mesh, theta=(0.0, theta2), joints=joints,
                                         n=len(reduced))
                print(row(f"{'':<14}FE", fe))
                print(row(f"{'':<10}gap [%]", _gap_percent(reduced, fe)))
            if args.table1 and theta2 == 0:
                reference = np.array(TABLE1_REFERENCE_HZ[joints][:len(reduced)])
                print(row(f"{'':<4}independent reference", reference))
                print(row(f"{'':<4}gap to reference [%]", _gap_percent(reduced[:len(reference)],
                                                                       reference)))
                referenced = True
    if mesh:
        print(f"FE: {mesh.element}, {mesh.elements_per_link[0]}+{mesh.elements_per_link[1]} "
              "elements; gap = (reduced - FE) / FE")
    if referenced:
        print("independent reference: a converged Euler-Bernoulli FE model of Table 1's arm, "
              "built outside this code (the paper publishes no frequencies)")
    return 0
