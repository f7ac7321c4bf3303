"""Validation of controllers and observers for the two-link flexible arm: one run, many
runs, verdicts and reports, and the ``flexarm`` command line.

The work flows through four rooms: `validation.run` (a scenario, its laws, the closed
loop, the result and its metrics), `validation.batch` (campaigns, where runs execute,
the results store and the code fingerprint), `validation.verdicts` (the paper's claims,
the stability map, attribution, regression bounds, linear validity: the ν-gap and the
stability margin) and `validation.report`.  The public
API is re-exported here and loaded on first use, so ``import validation`` stays cheap::

    from validation import run_scenario, scenario_from_mapping
    result = run_scenario(scenario_from_mapping({"duration": 5.0}))
    t, y = result

Nothing else in the project imports this package.
"""
from __future__ import annotations

import importlib

#: Public name → the module that defines it.
_EXPORTS = {
    "Scenario": "run.scenario", "scenario_from_mapping": "run.scenario",
    "scenario_to_mapping": "run.scenario", "ConfigError": "run.config",
    "load_toml": "run.tomlfiles", "simulate": "run.loop", "run_scenario": "run.loop",
    "build": "run.loop", "RunResult": "run.results", "all_metrics": "run.metrics",
    "Campaign": "batch.campaign", "load_campaign": "batch.campaign",
    "campaign_from_mapping": "batch.campaign", "expand": "batch.campaign",
    "run_campaign": "batch.queue", "make_runner": "batch.executor",
    "ResultStore": "batch.store.folder",
    "nu_gap": "verdicts.nugap", "stability_margin": "verdicts.nugap",
    "reduced_linear_model": "verdicts.linear", "law_gain": "verdicts.linear",
    "read_experiment": "run.experiments", "read_frequency_response": "run.experiments",
    "base_scenario": "verdicts.calibration", "calibration_settings": "verdicts.calibration",
    "plan_calibration": "verdicts.calibration", "calibrate": "verdicts.calibration",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'validation' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
