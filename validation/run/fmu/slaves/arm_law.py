"""A scenario's controller and observer as a co-simulation FMU (FMI 2.0, built with
pythonfmu by `validation.run.fmu.export`): the source the FMU carries and runs, with the
interpreter of the environment that imports it (it imports this project's packages).

Inputs: what the observer measures (``theta<i>``, ``q<i><j>``, ``…_dot``; with no
observer, the whole state [θ, q, θ̇, q̇], as ``feedback = "true"``) and the reference
``theta<i>_ref``, ``theta<i>_dot_ref``, ``theta<i>_ddot_ref``; outputs the torques
``tau<i>`` [N m]; parameters the laws' numeric options (``controller.<option>``,
``observer.<option>``).  ``doStep(t, Ts)`` samples the inputs at t and outputs the torque
to hold over [t, t + Ts): a master that steps this FMU before the plant in each period
(Gauss–Seidel) closes the toolkit's loop; the observer is fed the torques it output."""
import json
from pathlib import Path

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

from controllers import CONTROLLERS, OBSERVERS, accepted_options, resolve
from validation.run.laws import build_controller, build_observer, nominal_model
from validation.run.loop import initial_state, make_reference
from validation.run.scenario import scenario_from_mapping

#: The file in the FMU's resources holding the scenario whose laws it runs.
DESCRIPTION = "arm_law.json"


class ArmLaws(Fmi2Slave):
    """A scenario's controller and observer behind the FMI 2.0 interface."""

    description = "A flexible arm's controller and observer, flexarm-validation"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._data = json.loads((Path(self.resources) / DESCRIPTION).read_text())
        s = scenario_from_mapping(self._data)
        self.options = {f"{role}.{k}": float(v) for role in ("controller", "observer")
                        for k, v in self._numeric_options(s, role).items()}
        self._build()
        N = self._model.n_joints
        self.y = np.zeros(len(self._inputs))
        self.ref = np.zeros(3 * N)
        self.tau = np.zeros(N)
        for i, name in enumerate(self._inputs):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        getter=lambda i=i: float(self.y[i]),
                                        setter=lambda v, i=i: self.y.__setitem__(i, v)))
        for i, name in enumerate(f"theta{j + 1}{d}_ref" for d in ("", "_dot", "_ddot")
                                 for j in range(N)):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        getter=lambda i=i: float(self.ref[i]),
                                        setter=lambda v, i=i: self.ref.__setitem__(i, v)))
        for i in range(N):
            self.register_variable(Real(f"tau{i + 1}", causality=Fmi2Causality.output,
                                        initial=Fmi2Initial.exact,
                                        getter=lambda i=i: float(self.tau[i])))
        for key in self.options:
            self.register_variable(Real(key, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed,
                                        getter=lambda k=key: self.options[k],
                                        setter=lambda v, k=key: self.options.__setitem__(k, v)))

    @staticmethod
    def _numeric_options(s, role: str) -> dict:
        """A law's options that are single numbers: those given, then its defaults."""
        spec = getattr(s, role)
        if role == "observer" and spec.kind == "none":
            return {}
        given = {**{k: v for k, v in (accepted_options(resolve(
            spec.kind, CONTROLLERS if role == "controller" else OBSERVERS, role)) or {}).items()
                    if k != "Ts"}, **spec.options}
        return {k: v for k, v in given.items()
                if isinstance(v, (int, float)) and not isinstance(v, bool)}

    def _build(self) -> None:
        """The laws of the scenario with the options set, reset at its initial state."""
        data = dict(self._data)
        for role in ("controller", "observer"):
            own = {k.partition(".")[2]: v for k, v in self.options.items()
                   if k.startswith(role + ".")}
            if own:
                data[role] = {**data[role], "options": {**data[role].get("options", {}), **own}}
        s = self._scenario = scenario_from_mapping(data)
        self._model = model = nominal_model(s.nominal_params, s.model_modes, s.model.kinematics)
        self._controller, self._observer = build_controller(s, model), build_observer(s, model)
        state = model.coordinate_names + tuple(f"{c}_dot" for c in model.coordinate_names)
        self._inputs = self._observer.measured if self._observer is not None else state
        x0 = initial_state(s, model)
        if self._observer is not None:
            self._observer.reset(x0 + s.initial_estimate_error())
        self._reference = make_reference(s.reference)
        self._last = np.zeros(model.n_joints)

    def exit_initialization_mode(self):
        self._build()

    def do_step(self, current_time, step_size):
        N, t = self._model.n_joints, current_time
        sampled = (self.ref[:N].copy(), self.ref[N:2 * N].copy(), self.ref[2 * N:].copy())
        ref = lambda at: sampled if at == t else self._reference(at)  # noqa: E731
        x = (self._observer.update(t, self.y.copy(), self._last)
             if self._observer is not None else self.y.copy())
        self.tau[:] = self._controller(t, x, ref)
        self._last = self.tau.copy()
        return True
