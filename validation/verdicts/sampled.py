"""Predicted and certified sampled-data stability of a stability-map case: the exact
zero-order-hold eigenvalues of the law's own linearised loop, and the ν-gap certificate.

A case (a resolved scenario mapping, as `validation.verdicts.stability` builds them) is
linearised at `POINTS` points of its run: at time t on the reference, the law is
linearised about the reference state x_d(t) = [θ_d, 0, θ̇_d, 0] (θ_d: one angle per joint) (`linear.law_gain`: every
gain it applies, from the law object itself, built exactly as a run builds it), and the
plant about rest at its configuration [θ_d(t), 0] (frozen time: the plant's
velocity-dependent Coriolis terms, second order in the reference rates of at most 1.3
rad/s, are left out).  The law is built at every period it is evaluated at, as a run at
that period builds it (a discrete design such as the LQR differs from period to period).

- **Predicted**: the largest Ts below which the sampled loop is stable at every point
  (`linear.largest_stable_period`), on the linearisation of the case's own plant — the
  reduced model, or the FE arm with the case's mesh (`plant_exudyn.linear_model`).  For a
  case with an observer the prediction is that of its controller fed the true state: an
  observer's internal state is not reachable through the plug-in interface (and the sign
  SMO is not differentiable), so the observer is not in the predicted loop.
- **Certified**: at a period Ts, δν(K P_red, K P_FE) < b(K P_red, I) at every point, with
  (P_red, P_FE) the ZOH models of the reduced and the FE arm from the torques to the state
  the law reads, and K the law's gain: the loop broken at the plant input, where the
  certificate of `validation.verdicts.nugap` says that the loop u = −K x closed around the
  FE arm is stable.  Broken there, the plant K P is dimensionless (torque to torque
  command) and weighted by the law itself; broken at the 2n outputs, the ν-gap would mix
  radians, metres and their rates and depend on their units (in SI units b ≤ 1/√(1 +
  σ_max(K)²) ≈ 0.03 for these laws, which certifies nothing).  The certified period is the
  largest Ts below which every tested period is certified.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
from dataclasses import dataclass

import control
import numpy as np

from reduced_model import cached_model

from ..run.config import ConfigError
from ..run.laws import build_controller, nominal_model
from ..run.loop import make_reference
from ..run.plants import truth_settings
from ..run.scenario import scenario_from_mapping
from ..run.specs import ObserverSpec
from .linear import (NotLinearisable, closed_loop_matrix, growth_rate, largest_stable_period,
                     law_gain, reduced_linear_model)
from .nugap import FactorisationError, as_statespace, gap_detail, margin_detail
from .predictions import PROBE_TS, prediction_key

__all__ = ["POINTS", "Prediction", "CertificateRow", "predicted_period", "prediction",
           "certificate", "certified_period"]

#: Operating points per case, evenly spread over its run.
POINTS = 5
#: The scan of the predicted period [s]: 0.01 µs (the FE Table-1 arm's limits are µs)
#: to 0.1 s.
_SCAN = (1e-8, 0.1, 49)
_PREDICTION_RTOL = 1e-3


@dataclass(frozen=True)
class Prediction:
    """Largest stable period ``period`` [s] (inf: stable up to 0.1 s; 0: unstable even at
    0.01 µs; NaN: no prediction), the θ2 [rad] of the operating point that limits it (NaN
    on a one-link arm), and a ``note`` (what the prediction leaves out, or why there is
    none)."""

    period: float
    theta2: float
    note: str


@dataclass(frozen=True)
class CertificateRow:
    """At period ``Ts`` [s]: the largest ν-gap and the smallest margin over the operating
    points (b = 0: the loop on the reduced model is unstable; δν NaN: not computable), and
    whether every point is certified (δν < b at that point)."""

    Ts: float
    nu_gap: float
    margin: float
    certified: bool


class _Case:
    """The linearisation of one case (module docstring)."""

    def __init__(self, config: dict) -> None:
        self.scenario = s = scenario_from_mapping(config)
        self.model = nominal_model(s.nominal_params, s.model.modes_per_link,
                                   s.model.kinematics)
        self.reference = make_reference(s.reference)
        self.names = list(self.model.state_names)
        n, self.joints = self.model.n, self.model.n_joints
        self.points = []
        for t in np.linspace(0.0, s.duration, POINTS):
            theta, rate, _ = self.reference(float(t))
            x = np.zeros(2 * n)
            x[:self.joints], x[n:n + self.joints] = theta, rate
            self.points.append((float(t), x))
        self._gains: dict = {}

    def gains(self, Ts: float) -> list[np.ndarray] | None:
        """The law's gain at every point when run at period Ts (None if the law cannot be
        built at that period)."""
        if Ts not in self._gains:
            try:  # built at the period it runs at, as a run builds it
                law = build_controller(dataclasses.replace(self.scenario, Ts=Ts), self.model)
            except (ConfigError, ValueError):
                self._gains[Ts] = None
            else:
                self._gains[Ts] = [law_gain(law, x, t, self.reference, shared=(self.model,))
                                   for t, x in self.points]
        return self._gains[Ts]

    def theta(self, point: int) -> np.ndarray:
        """The joint angles [rad] of an operating point."""
        return self.points[point][1][:self.joints]

    def reduced_plant(self, point: int, *, nominal: bool = False,
                      forces: bool = False) -> control.StateSpace:
        """The reduced plant of the case (``nominal``: the law's own model) linearised at
        a point, its q outputs in the law's modal basis (as `ReducedPlant` reports them)."""
        s = self.scenario
        own = nominal or (s.true_params == s.nominal_params
                          and tuple(s.plant.modes_per_link) == self.model.modes_per_link)
        model = self.model if own else cached_model(s.true_params, tuple(s.plant.modes_per_link))
        return reduced_linear_model(model, theta=self.theta(point),
                                    modal_basis=None if own else self.model.mode_shapes,
                                    generalised_forces=forces)

    def fe_plant(self, point: int, settings) -> control.StateSpace:
        """The truth plant of ``settings`` linearised at a point (its kind's
        ``linear_model``; NotImplementedError for a kind without one)."""
        return settings.linear_model(self.scenario.true_params, theta=self.theta(point),
                                     model=self.model)


@functools.lru_cache(maxsize=128)
def _case(config_json: str) -> _Case:
    return _Case(json.loads(config_json))


def _observer(config: dict) -> str:
    """The observer of the case ``config`` (the one its key leaves out), read without
    checking the case (one that does not build has no prediction, which says why)."""
    return config.get("observer", {}).get("kind", ObserverSpec.kind)


@functools.lru_cache(maxsize=256)
def _prediction(config_json: str) -> Prediction:
    try:
        case = _case(config_json)
    except (ConfigError, ValueError) as exc:
        return Prediction(math.nan, math.nan, f"the case does not build: {exc}")
    spec = case.scenario.plant
    try:
        K0 = case.gains(case.scenario.Ts)
    except NotLinearisable as exc:
        return Prediction(math.nan, math.nan, f"{case.scenario.controller.kind}: {exc}")
    except Exception as exc:  # noqa: BLE001 - a plug-in law may raise anything: no prediction
        return Prediction(math.nan, math.nan, f"{case.scenario.controller.kind} raised "
                          f"{type(exc).__name__} while being linearised: {exc}")
    if K0 is None:
        return Prediction(math.nan, math.nan, f"the law does not build at Ts = {PROBE_TS:g} s")
    forces = K0[0].shape[0] > case.joints
    if forces and not spec.generalised_forces:
        return Prediction(math.nan, math.nan, "the law applies forces on the modal "
                          f"coordinates: the {spec.label} has {case.joints} actuators")
    truth = spec if spec.role == "truth" else None
    limit, where = math.inf, math.nan
    for i in range(len(case.points)):
        try:
            plant = case.fe_plant(i, truth) if truth is not None else \
                case.reduced_plant(i, forces=forces)
        except NotImplementedError as exc:
            return Prediction(math.nan, math.nan, str(exc))

        def growth(Ts, i=i, plant=plant):
            gains = case.gains(Ts)
            if gains is None:
                return math.inf
            return growth_rate(closed_loop_matrix(control.sample_system(plant, Ts), gains[i],
                                                  case.names), Ts)

        value = largest_stable_period(growth, low=_SCAN[0], high=_SCAN[1], points=_SCAN[2],
                                      rtol=_PREDICTION_RTOL)
        if value < limit:
            theta = case.theta(i)
            limit, where = value, float(theta[1]) if len(theta) > 1 else math.nan
    return Prediction(limit, where, "")


def prediction(config: dict) -> Prediction:
    """The predicted largest stable period of a stability-map case on the linearisation
    of its own plant (module docstring), with the θ2 that limits it and a note."""
    predicted = _prediction(prediction_key(config))
    observer = _observer(config)
    if observer == "none" or predicted.note:
        return predicted
    return dataclasses.replace(predicted, note=f"the controller fed the true state "
                                               f"({observer} not in the loop)")


def predicted_period(config: dict) -> float:
    """`prediction`'s period [s] alone (NaN when there is none)."""
    return prediction(config).period


def certificate(config: dict, periods) -> list[CertificateRow]:
    """The ν-gap certificate of a case's law against its truth plant (`truth_settings`: the
    case's own, or the default truth kind for a reduced-plant case) at ``periods`` [s]
    in increasing order, up to the first that is not certified (module docstring).
    Empty for a law that cannot be certified (forces on the modal coordinates, an
    observer in the loop, not linearisable, a truth plant without a linearisation)."""
    if _observer(config) != "none":
        return []
    case = _case(prediction_key(config))
    spec = truth_settings(config)
    reduced = [case.reduced_plant(i, nominal=True)[case.names, :]
               for i in range(len(case.points))]
    try:
        fe = [case.fe_plant(i, spec)[case.names, :] for i in range(len(case.points))]
    except NotImplementedError:
        return []
    rows = []
    for Ts in sorted(periods):
        try:
            gains = case.gains(Ts)
        except NotLinearisable:
            return []
        if gains is None:
            rows.append(CertificateRow(Ts, math.nan, 0.0, False))
            continue
        if gains[0].shape[0] > case.joints:
            return []
        gaps, margins = [], []
        for P_red, P_fe, K in zip(reduced, fe, gains):
            gain = as_statespace(K)
            loop_red = gain * control.sample_system(P_red, Ts)
            margins.append(margin_detail(loop_red, np.eye(case.joints)).value)
            try:
                gaps.append(gap_detail(loop_red, gain * control.sample_system(P_fe, Ts)).value)
            except FactorisationError:
                gaps.append(math.nan)  # no ν-gap: not certified

        rows.append(CertificateRow(Ts, float(np.max(gaps)), min(margins),
                                   all(g < b for g, b in zip(gaps, margins))))
        if not rows[-1].certified:
            break  # the certified period ends here (`certified_period`)
    return rows


def certified_period(rows: list[CertificateRow]) -> float:
    """The largest tested Ts below which every tested period is certified (0 if the
    smallest is not; NaN without rows)."""
    if not rows:
        return math.nan
    best = 0.0
    for row in sorted(rows, key=lambda r: r.Ts):
        if not row.certified:
            break
        best = row.Ts
    return best
