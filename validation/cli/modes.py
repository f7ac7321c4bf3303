"""``flexarm modes``: natural frequencies of the reduced model, the FE model and an
independent reference; ``flexarm arms``: the shipped arms."""
from __future__ import annotations

import argparse

import numpy as np

from ..run.arms import arm_description, arm_of
from ..run.config import ConfigError, check
from ..run.tomlfiles import load_toml


#: Independent reference frequencies [Hz] of Table 1's arm at θ1 = θ2 = 0: a converged
#: Euler–Bernoulli finite-element model built outside this code (the paper publishes
#: none).  Joints free: the two rigid modes left out.
TABLE1_REFERENCE_HZ = {"locked": (0.6316, 3.8312, 6.3499, 33.665),
                       "free": (2.2359, 6.1233, 31.414, 34.302)}


def _gap_percent(ours, reference) -> np.ndarray:
    """100 (ours − reference)/reference, rounded to the printed 4 decimals with no −0."""
    return np.round(100 * (np.asarray(ours) - reference) / reference, 4) + 0.0


def _arm(args: argparse.Namespace):
    """The arm ``--arm`` names, its flat keys changed by ``--params``; and how to name it."""
    from reduced_model import ArmParameters
    params, source = arm_of(args.arm), arm_description(args.arm)
    if args.params:
        data = load_toml(args.params)
        if set(data) == {"params"} and isinstance(data["params"], dict):
            data = data["params"]
        params = ArmParameters.from_mapping(data, where=f"{args.params}:params", base=params)
        source = f"{source}, changed by {args.params}"
    return params, source


def cmd_modes(args: argparse.Namespace) -> int:
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel, validate_modes_per_link
    if args.table1:
        raise ConfigError("--table1", "is now --arm table1")
    params, source = _arm(args)
    modes = None if args.modes_per_link is None else validate_modes_per_link(
        args.modes_per_link, params, where="--modes-per-link")
    model = ArmModel(params, modes)
    N = model.n_joints
    check(N >= 2 or args.theta2 == [0.0], "--theta2", "needs a joint 2: this arm has one link")
    mesh = Mesh(element=args.element, elements_per_link=args.elements) if args.compare else None
    referenced = args.arm == "table1" and not args.params
    row = lambda label, values: f"  {label:<30}" + "".join(f"{v:>11.4f}" for v in values)  # noqa: E731
    print(f"Reduced model, {'+'.join(map(str, model.modes_per_link))} clamped-mass modes "
          f"(0: a rigid link), arm: {source}")
    print("Clamped-mass link frequencies [Hz]")
    for i, shapes in enumerate(model.mode_shapes, start=1):
        print(row(f"link {i}", shapes.frequencies_hz) if len(shapes.frequencies_hz)
              else f"  link {i:<25} rigid")
    for theta2 in args.theta2:
        Q, theta = np.zeros(model.n), np.zeros(N)
        if N >= 2:
            Q[1] = theta[1] = theta2
        print(f"Coupled frequencies at theta1 = 0, theta2 = {theta2:g} rad [Hz]" if N >= 2
              else "Coupled frequencies [Hz]")
        for joints in ("locked", "free"):
            reduced = model.natural_frequencies(Q, joints)
            label = "joints locked" if joints == "locked" else "joints free (non-zero)"
            print(row(label + (" reduced" if mesh else ""), reduced))
            if mesh:
                fe = natural_frequencies(params, mesh, theta=tuple(theta), joints=joints,
                                         n=len(reduced))
                print(row(f"{'':<14}FE", fe))
                print(row(f"{'':<10}gap [%]", _gap_percent(reduced, fe)))
            if referenced and theta2 == 0:
                reference = np.array(TABLE1_REFERENCE_HZ[joints][:len(reduced)])
                print(row(f"{'':<4}independent reference", reference))
                print(row(f"{'':<4}gap to reference [%]", _gap_percent(reduced[:len(reference)],
                                                                       reference)))
    if mesh:
        counts = "+".join(str(n) for n in mesh.counts(params) if n)
        print(f"FE: {mesh.element}, {counts} elements; gap = (reduced - FE) / FE")
    if referenced:
        print("independent reference: a converged Euler-Bernoulli FE model of Table 1's arm, "
              "built outside this code (the paper publishes no frequencies)")
    return 0


def _link_text(link) -> str:
    kind = "rigid" if link.rigid else \
        f"flexible, {link.modes} modes, EI {link.bending_stiffness:g} N m²"
    return f"{link.length:g} m, {link.mass_per_length:g} kg/m, {kind}"


def cmd_arms(args: argparse.Namespace) -> int:
    """``flexarm arms``: the shipped arms, or one arm in full."""
    from reduced_model import ArmModel, named_arms
    if args.arm is None:
        shipped = named_arms()
        width = max(map(len, shipped))
        print(f"{len(shipped)} shipped arms (flexarm arms NAME for one; --arm NAME or an arm "
              "file for a run):")
        for name, description in shipped.items():
            arm = arm_of(name)
            links = "+".join("R" if link.rigid else "F" for link in arm.links)
            vertical = "vertical" if any(arm.gravity) else "horizontal"
            print(f"  {name:<{width}}  {links:<7} {vertical:<10}  {description}")
        print("links: F flexible, R rigid, from the base out")
        return 0
    arm = arm_of(args.arm)
    model = ArmModel(arm)
    print(f"arm {args.arm}: {arm_description(args.arm)}")
    for i, link in enumerate(arm.links):
        hz = ", ".join(f"{f:.4g}" for f in model.mode_shapes[i].frequencies_hz)
        print(f"  link {i + 1}: {_link_text(link)}; hub {link.hub_mass:g} kg, "
              f"{link.hub_inertia:g} kg m²" + (f"; clamped-mass modes {hz} Hz" if hz else ""))
    print(f"  payload: {arm.payload.mass:g} kg, {arm.payload.inertia:g} kg m²")
    print(f"  gravity: ({arm.gravity[0]:g}, {arm.gravity[1]:g}) m/s²"
          + (" (horizontal arm)" if not any(arm.gravity) else ""))
    print(f"  joints: {arm.joints_text() or 'ideal'}")
    print(f"  flat keys: {', '.join(arm.keys())}")
    return 0
