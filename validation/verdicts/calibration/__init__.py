"""Calibration: the plant's physical parameters fitted to measured experiments, with
honest uncertainty and a verdict on the model (``flexarm calibrate``).

The rooms of a calibration, in the order a fit uses them:

* `settings` — the ``[calibrate]`` table and ``--fit``, checked against the scenario
  (`joints`: the starts and bounds of friction and drive fields);
* `plan` — every experiment and frequency response checked before anything is written,
  and the plant's linearised response; `units` — angles in degrees refused;
* `problem` — the residuals at any point, each simulation a stored run (a failed one is
  no data: `FitFailed` where a result would rest on it);
* `fit` — the bounded least-squares fit and its verdict (`polish`: refined at the scale
  of the uncertainty; `differences`: the Jacobians, each column checked for jumps);
* `adequacy` — the residual tests and the verdict on the model (`noise`: coloured
  measurement noise and its model);
* `intervals` — standard errors, intervals and identifiability;
* `extensions` — the physics an inadequate model may lack, screened;
* `workflow` — the whole calibration (`calibrate`): the fit, the extensions fitted and
  ranked, the comparison with other fits (`comparison`) and the files (`outputs`).
"""
from __future__ import annotations

from .comparison import data_fingerprint, read_fits
from .workflow import calibrate
from .outputs import CALIBRATION_VERDICTS, EXTENDED, RESULT_FILES, refuse_links
from .plan import Plan, Target, linear_response, plan_calibration
from .problem import FitFailed
from .settings import CalibrationSettings, Parameter, base_scenario, calibration_settings

__all__ = ["calibrate", "calibration_settings", "base_scenario", "plan_calibration",
           "linear_response", "Plan", "Target", "CalibrationSettings", "Parameter",
           "data_fingerprint", "read_fits", "refuse_links", "RESULT_FILES", "EXTENDED",
           "CALIBRATION_VERDICTS", "FitFailed"]
