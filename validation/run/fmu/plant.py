"""The FMU plant: one instance of a co-simulation FMU (FMI 2.0 or 3.0, through FMPy)
stepped one control period per communication step, its truth read from the outputs its
table maps (`validation.run.fmu.settings`).  A Python plant: the closed loop steps it as
every plant without a compiled form (`validation.run.loop`); its ``doStep`` holds the
torques over the period and the FMU's own solver steps inside it, as the exact hold of
the built-in plants does."""
from __future__ import annotations

import importlib
import weakref
from pathlib import Path

import numpy as np

from reduced_model import Plant, PlantFailure, truth_extras

from ..config import short_str
from .description import fmpy, read_description, signal_names, unpacked

__all__ = ["FmuPlant"]


class FmuPlant(Plant):
    """A co-simulation FMU as the plant (``kind = "fmu"``; its role is its table's).

    Parameters
    ----------
    settings : FmuSettings
        The plant table: the FMU and what its variables mean.
    params : ArmParameters
        The true arm (its mapped parameters are set on the FMU at every reset).
    model : ArmModel
        The laws' model: its coordinates are the plant's, its kinematics and mode shapes
        give what the FMU does not output.
    sensors : SensorConfig
        What is measured.
    Ts : float
        The control period [s]: the communication step.
    """

    label = "FMU plant"

    def __init__(self, settings, params, *, model, sensors, Ts: float) -> None:
        self.role = settings.role
        self.label = settings.label
        self.model, self.params, self.fmu = model, params, settings.fmu
        N, n = model.n_joints, model.n
        md = read_description(settings.fmu)
        found = settings.variables(N, model.modes_per_link)
        names = signal_names("outputs", N, model.modes_per_link)
        self._in_vr = [v.valueReference for v in found["inputs"].values()]
        self._out_vr = [v.valueReference for v in found["outputs"].values()]
        self._out_at = np.array([names.index(k) for k in found["outputs"]], dtype=np.int64)
        state = signal_names("initial", N, model.modes_per_link)
        self._init_vr = [v.valueReference for v in found["initial"].values()]
        self._init_at = [state.index(k) for k in found["initial"]]
        self._param_vr = [v.valueReference for v in found["parameters"].values()]
        self._param_values = [float(params.get(k)) for k in found["parameters"]]
        mapped = set(found["outputs"])
        extras = truth_extras(N)
        #: What the laws' model computes: the tips, tip deflections, motors not output.
        self._tips = not all(f"tip{k}_{a}" in mapped for k in range(1, N + 1) for a in "xy")
        self._defl = [k for k in range(N) if f"tip_defl{k + 1}" not in mapped]
        self._motor = [k for k in range(2 * N) if extras[4 * N + k] not in mapped]
        self._fmi3 = md.fmiVersion.startswith("3")
        fmpy()  # FMPy itself, or the install line
        kind = (importlib.import_module("fmpy.fmi3").FMU3Slave if self._fmi3 else
                importlib.import_module("fmpy.fmi2").FMU2Slave)
        self._slave = kind(guid=md.guid if not self._fmi3 else md.instantiationToken,
                           unzipDirectory=unpacked(settings.fmu),
                           modelIdentifier=md.coSimulation.modelIdentifier,
                           instanceName=Path(settings.fmu).stem)
        self._slave.instantiate()
        self._live = False  # initialised since instantiated or reset
        weakref.finalize(self, _release, self._slave)
        Plant.__init__(self, sensors, model.mode_shapes, Ts, Ts)
        self._n = n
        self._truth = np.zeros(self.truth_size)

    # --- FMI calls ----------------------------------------------------------------------
    def _set(self, vrs, values) -> None:
        if vrs:
            (self._slave.setFloat64 if self._fmi3 else self._slave.setReal)(vrs, list(values))

    def _get(self, vrs) -> list:
        return (self._slave.getFloat64 if self._fmi3 else self._slave.getReal)(vrs)

    def _reset(self, x0: np.ndarray) -> None:
        """A fresh start of the same instance (FMI reset), the true arm's parameters and
        the initial state set, the truth read."""
        s = self._slave
        try:
            if self._live:
                s.reset()
            if self._fmi3:
                s.enterInitializationMode(startTime=0.0)
            else:
                s.setupExperiment(startTime=0.0)
                s.enterInitializationMode()
            self._set(self._param_vr, self._param_values)
            self._set(self._init_vr, x0[self._init_at])
            s.exitInitializationMode()
        except Exception as exc:  # noqa: BLE001 - FMPy's or the FMU's own error
            raise PlantFailure(f"{Path(self.fmu).name}: initialisation failed "
                               f"({short_str(exc)})") from None
        self._live = True
        self._read()
        N, m = self.n_joints, self._n
        start = np.concatenate([self._truth[:N], self._truth[m:m + N]])
        wanted = np.concatenate([x0[:N], x0[m:m + N]])
        if not np.allclose(start, wanted, rtol=0.0, atol=1e-12):
            raise PlantFailure(f"{Path(self.fmu).name} starts at theta, theta_dot = "
                               f"{np.round(start, 6).tolist()}, the run at "
                               f"{np.round(wanted, 6).tolist()}: map its initial state "
                               "(plant.initial)")

    def _advance(self, tau: np.ndarray, tip_force) -> None:
        """One communication step of ``Ts`` from ``time`` with ``tau`` held."""
        if tip_force is not None and np.any(tip_force):
            raise PlantFailure("an FMU plant takes the joint torques only (no payload force)")
        try:
            self._set(self._in_vr, tau)
            self._slave.doStep(currentCommunicationPoint=self.time,
                               communicationStepSize=self.Ts)
            self._read()
        except Exception as exc:  # noqa: BLE001 - FMPy's or the FMU's own error
            raise PlantFailure(f"{Path(self.fmu).name}: doStep from t = {self.time:.6g} s "
                               f"failed ({short_str(exc)})") from None

    def _read(self) -> None:
        """The truth vector from the mapped outputs and, for what is not mapped, the
        laws' model (`FmuSettings`)."""
        t, N, m = self._truth, self.n_joints, self._n
        t[:] = 0.0
        t[self._out_at] = self._get(self._out_vr)
        o = 2 * m
        if self._tips:
            t[o:o + 2 * N] = self.model.tip_position(t[:m]).ravel()
        if self._defl:
            t[o + 2 * N + np.array(self._defl)] = self.model.tip_deflection(t[:m])[self._defl]
        for k in self._motor:  # a joint without a drive: its encoder reads θ
            t[o + 4 * N + k] = t[k] if k < N else t[m + k - N]

    # --- the contract -------------------------------------------------------------------
    @property
    def state_size(self) -> int:
        """Length of [θ, q, θ̇, q̇] in the laws' coordinates."""
        return 2 * self._n

    def truth_into(self, out: np.ndarray) -> None:
        out[:] = self._truth

    def joint_state(self):
        N, m = self.n_joints, self._n
        return self._truth[:N].copy(), self._truth[m:m + N].copy()

    def modal_state(self):
        N, m = self.n_joints, self._n
        return self._truth[N:m].copy(), self._truth[m + N:2 * m].copy()

    def field_sampler(self, link: int, x, derivative: int):
        c = self.n_joints + sum(b.n for b in self.modal_basis[:link])
        basis = self.modal_basis[link].evaluate(x, derivative).T
        coords = slice(c, c + self.modal_basis[link].n)
        return lambda: basis @ self._truth[coords]

    def tip_positions(self) -> np.ndarray:
        o, N = 2 * self._n, self.n_joints
        return self._truth[o:o + 2 * N].reshape(N, 2).copy()


def _release(slave) -> None:
    """End an FMU instance (when its plant is collected)."""
    try:
        slave.terminate()
    except Exception:  # noqa: BLE001 - not initialised, or already failed: free it anyway
        pass
    slave.freeInstance()
