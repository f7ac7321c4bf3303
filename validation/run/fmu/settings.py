"""``[plant] kind = "fmu"``: the plant table of a co-simulation FMU (FMI 2.0 or 3.0) and
its checks — which FMU, the role it plays, and the table that maps the plant contract
(`reduced_model.Plant`) to the FMU's variables: the joint torques in, the truth out
(joint angles and rates; modal coordinates, tips, tip deflections where it has them),
initial states and the true arm's parameters set by name.

A name the table leaves out maps to the FMU's variable of the same name where it has
one; the joint torques, angles and rates, and whatever the sensors measure, must map.
Everything is checked against the FMU's model description before anything runs
(`check`, `check_with`): each refusal is one line naming the key."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from reduced_model import FieldError, PlantSettings, ROLES

from ..config import ConfigError, check
from .description import read_description, signal_names, unpacked, variable

__all__ = ["FmuSettings", "TABLES"]

#: The mapping tables, each with the causality its FMU variables must have and the
#: contract names it takes.
TABLES = {"inputs": ("input",), "outputs": ("output",), "initial": ("parameter",),
          "parameters": ("parameter",)}
_NAMES = {"inputs": re.compile(r"tau\d+"),
          "outputs": re.compile(r"(theta\d+|q\d+)(_dot)?|tip\d+_[xy]|tip_defl\d+|proj_res\d+"
                                r"|motor\d+(_dot)?"),
          "initial": re.compile(r"(theta\d+|q\d+)(_dot)?")}


@dataclass(frozen=True)
class FmuSettings(PlantSettings):
    """``kind = "fmu"``: a co-simulation FMU (FMI 2.0 or 3.0) as the plant, through FMPy
    (the ``fmi`` extra); the communication step is the control period ``Ts``.

    Parameters
    ----------
    kind : {"fmu"}
        Selects this plant.
    fmu : str
        The ``.fmu`` file, from the folder the command runs in (its SHA-256 and FMPy's
        version enter each run's fingerprint).
    role : {"truth", "reduced"}
        The role the FMU plays, required.
    inputs : dict
        ``tau<i>`` → the FMU input taking joint i's torque [N m].
    outputs : dict
        A truth entry (``theta<i>``, ``theta<i>_dot``, ``q<i><j>`` and ``_dot`` in the
        laws' modal basis, ``tip<i>_x``/``_y``, ``tip_defl<i>``, ``proj_res<i>``,
        ``motor<i>`` and ``_dot``) → the FMU output giving it [rad, rad/s, m].  An entry
        it has no output for is computed from the others by the laws' model (q: 0; tips:
        its kinematics; tip deflections: its mode shapes; motors: the joints).
    initial : dict
        A state coordinate (``theta<i>``, ``theta<i>_dot``, …) → the FMU parameter that
        sets its value at t = 0 (the run's initial state).
    parameters : dict
        A flat key of the true arm (``L1``, ``EI2``, ``Mp``, …) → the FMU parameter set
        to its value: uncertainty, sweeps and calibration vary the FMU through it.
    step_cost_s : float
        A pessimistic wall time per control period [s], for the runs' time limits.
    """

    kind: str = "fmu"
    fmu: str = ""
    role: str | None = None
    inputs: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)
    initial: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    step_cost_s: float = 1e-3

    def __post_init__(self):
        if self.kind != "fmu":
            raise FieldError("plant", "kind", f"must be 'fmu', got {self.kind!r}")
        check(bool(self.fmu), "fmu", "names the .fmu file to run (a path)")
        check(self.role is not None, "role", "an FMU plant must say its role: 'truth' "
                                                   "(the arm verdicts trust) or 'reduced'")
        check(self.role in ROLES, "role",
              f"must be one of {', '.join(map(repr, ROLES))}, got {self.role!r}")
        check(math.isfinite(self.step_cost_s) and self.step_cost_s > 0, "step_cost_s",
              f"must be > 0, got {self.step_cost_s!r}")
        for table in TABLES:
            for name, target in getattr(self, table).items():
                check(isinstance(target, str) and bool(target), f"{table}.{name}",
                      f"must name a variable of the FMU (a string), got {target!r}")
                if table != "parameters":  # flat keys of the arm: checked with it
                    check(bool(_NAMES[table].fullmatch(name)), f"{table}.{name}",
                          f"is not a name of the plant contract's {table} "
                          f"({_NAMES[table].pattern})")

    @property
    def label(self) -> str:
        return f"{self.role} plant (FMU {Path(self.fmu).name})"

    @property
    def generalised_forces(self) -> bool:
        return False  # the joint torques only

    def check(self) -> None:
        """ConfigError naming the key unless the FMU is a co-simulation FMU of FMI 2.0 or
        3.0 with every variable the tables name, of the causality each needs (the names
        that depend on the arm: `check_with`)."""
        md = read_description(self.fmu)
        for table, causalities in TABLES.items():
            for name, target in getattr(self, table).items():
                variable(md, target, f"plant.{table}.{name}", causalities, self.fmu)
        unpacked(self.fmu)  # once, here: workers forked after the check share it

    def check_with(self, params, modes_per_link, measured) -> None:
        """ConfigError naming the key unless the FMU takes the joint torques of ``params``
        (the true arm) and gives its joint angles, rates and the ``measured`` coordinates,
        the mapped names are the arm's, and each mapped parameter is one of its numbers."""
        self.variables(params.n_links, modes_per_link, measured)
        for key in self.parameters:
            try:
                value = params.get(key)
            except FieldError as exc:
                raise ConfigError(f"plant.parameters.{key}", exc.reason) from None
            check(isinstance(value, (int, float)), f"plant.parameters.{key}",
                  f"is not one number of the arm (got {value!r})")

    def variables(self, links: int, modes_per_link, measured=()) -> dict:
        """Each table's contract name → the FMU variable it maps to (`check_with`'s
        checks): what a plant of this table reads and writes."""
        md = read_description(self.fmu)
        required = {f"{c}{d}" for i in range(links) for c, d in
                    ((f"theta{i + 1}", ""), (f"theta{i + 1}", "_dot"))}
        required |= {m for m in measured if _NAMES["initial"].fullmatch(m)}
        required |= set(signal_names("inputs", links, modes_per_link))
        own = {v.name: v for v in md.modelVariables}
        out = {}
        for table, causalities in TABLES.items():
            given = getattr(self, table)
            if table == "parameters":
                out[table] = {k: variable(md, v, f"plant.{table}.{k}", causalities, self.fmu)
                              for k, v in given.items()}
                continue
            names = signal_names(table, links, modes_per_link)
            for name in given:
                check(name in names, f"plant.{table}.{name}",
                      f"is not a name of this {links}-link arm's {table}")
            found = {}
            for name in names:
                key = f"plant.{table}.{name}"
                if name in given:
                    found[name] = variable(md, given[name], key, causalities, self.fmu)
                elif table != "initial" and name in own and own[name].causality in causalities:
                    found[name] = variable(md, name, key, causalities, self.fmu)
                else:
                    check(table == "initial" or name not in required, key,
                          f"{Path(self.fmu).name} has no {causalities[0]} {name!r}: map one "
                          f"(plant.{table}.{name} = \"<its variable>\")")
            out[table] = found
        return out

    def build(self, params, model, sensors, Ts):
        from .plant import FmuPlant
        return FmuPlant(self, params, model=model, sensors=sensors, Ts=Ts)

    def step_cost(self) -> float:
        return self.step_cost_s
