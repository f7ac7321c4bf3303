"""``flexarm export-fmu``: a scenario's reduced plant and its laws written as
co-simulation FMUs (`validation.run.fmu.export`)."""
from __future__ import annotations

import argparse

from ..run.config import check
from .one_run import scenario_from_args


def cmd_export_fmu(args: argparse.Namespace) -> int:
    from ..run.fmu.export import export_law, export_plant
    from ..run.fmu import signal_names
    check(bool(args.plant_fmu or args.law_fmu), "export-fmu",
          "name what to write: --plant-fmu FILE.fmu, --law-fmu FILE.fmu or both")
    if args.plant_fmu and args.law_fmu:
        check(args.plant_fmu != args.law_fmu, "--law-fmu", "must differ from --plant-fmu")
    scenario, notes = scenario_from_args(args)
    for note in notes:
        print(note)
    if args.plant_fmu:
        built = export_plant(scenario, args.plant_fmu)
        N = scenario.true_params.n_links
        print(f"wrote {built}: the reduced plant of the {scenario.arm} arm (inputs "
              f"{', '.join(signal_names('inputs', N, ()))}; outputs the truth vector; "
              "parameters its flat keys, step and <coordinate>_0)")
        print(f'  as a plant: [plant] kind = "fmu", fmu = "{built}", role = "reduced"')
    if args.law_fmu:
        built = export_law(scenario, args.law_fmu)
        print(f"wrote {built}: {scenario.controller.kind} + {scenario.observer.kind} at "
              f"Ts = {scenario.Ts:g} s (inputs the measurements and the reference; outputs "
              "the torques)")
    print("  the FMUs run Python: the importing tool needs this environment's interpreter "
          "with pythonfmu")
    return 0
