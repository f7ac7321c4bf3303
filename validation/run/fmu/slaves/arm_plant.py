"""The reduced plant of an arm description as a co-simulation FMU (FMI 2.0, built with
pythonfmu by `validation.run.fmu.export`): the source the FMU carries and runs, with the
interpreter of the environment that imports it (it imports this project's
`reduced_model`).

Inputs ``tau<i>`` [N m]; outputs the truth vector (`reduced_model.truth_extras`: θ, q,
θ̇, q̇ in the plant's own modal basis, tips, tip deflections, projection residuals,
motors); parameters every number of the arm by its flat key (``L1``, ``EI2``, ``Mp``…),
the RK4 step ``step`` and the initial state ``<coordinate>_0``.  Each communication step
holds the torques over it exactly (`reduced_model.ReducedPlant`); its length is fixed by
the first step."""
import json
from pathlib import Path

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

from reduced_model import ReducedPlant, coordinate_names, truth_extras
from reduced_model.arm import arm_from_table

#: The file in the FMU's resources that describes its arm (written by the export).
DESCRIPTION = "arm_plant.json"


class ReducedArmPlant(Fmi2Slave):
    """The reduced plant (`reduced_model.ReducedPlant`) behind the FMI 2.0 interface."""

    description = "The reduced (assumed-modes) plant of a flexible arm, flexarm-validation"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        spec = json.loads((Path(self.resources) / DESCRIPTION).read_text())
        self._arm = arm_from_table(spec["arm"])
        self._modes, self._kinematics = tuple(spec["modes_per_link"]), spec["kinematics"]
        self.numbers = {k: float(self._arm.get(k)) for k in self._arm.keys()
                        if isinstance(self._arm.get(k), float)}
        self.step = float(spec["step"])
        N = self._arm.n_links
        coords = coordinate_names(self._modes)
        self._state_names = coords + tuple(f"{c}_dot" for c in coords)
        self.x0 = np.zeros(len(self._state_names))
        self.tau = np.zeros(N)
        self._plant, self._truth, self._Ts = None, None, None
        self._build(self.step)
        for i in range(N):
            self.register_variable(Real(f"tau{i + 1}", causality=Fmi2Causality.input,
                                        getter=lambda i=i: float(self.tau[i]),
                                        setter=lambda v, i=i: self.tau.__setitem__(i, v)))
        for i, name in enumerate(self._state_names + truth_extras(N)):
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        initial=Fmi2Initial.exact,
                                        getter=lambda i=i: float(self._truth[i])))
        for key in self.numbers:
            self.register_variable(Real(key, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed,
                                        getter=lambda k=key: self.numbers[k],
                                        setter=lambda v, k=key: self.numbers.__setitem__(k, v)))
        self.register_variable(Real("step", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed))
        for i, name in enumerate(self._state_names):
            self.register_variable(Real(f"{name}_0", causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed,
                                        getter=lambda i=i: float(self.x0[i]),
                                        setter=lambda v, i=i: self.x0.__setitem__(i, v)))

    def _build(self, Ts: float) -> None:
        """The plant of the arm with the parameters set, at rest in ``x0``, holding each
        torque for ``Ts``."""
        arm = self._arm.replace(**{k: v for k, v in self.numbers.items()
                                   if v != self._arm.get(k)})
        self._plant = ReducedPlant(arm, Ts=Ts, modes_per_link=self._modes, step=self.step,
                                   kinematics=self._kinematics)
        self._plant.reset(self.x0)
        self._truth, self._Ts = self._plant.truth_vector(), Ts

    def exit_initialization_mode(self):
        self._build(self.step)

    def do_step(self, current_time, step_size):
        if current_time == 0.0 and step_size != self._Ts:
            self._build(step_size)  # the communication step: fixed by the first
        if abs(step_size - self._Ts) > 1e-12 * self._Ts:
            self.log(f"the communication step is {self._Ts} s, got {step_size} s")
            return False
        self._plant.advance(self.tau)
        self._plant.truth_into(self._truth)
        return True
