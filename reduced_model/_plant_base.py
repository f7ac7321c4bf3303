"""The plant contract: what the closed loop of `validation` needs of a plant, and the
base class that owns what every plant shares.

A plant simulates the two-link arm from joint torques held over each control period and
reports what really happened in the reduced model's coordinates.  To write one (a second
FE engine, a user's model, hardware), subclass `Plant`:

1. Set ``name`` (a short label) and ``role``: "truth" (the arm verdicts trust; its
   results are checked under refinement) or "reduced" (the paper's model).
2. Call ``Plant.__init__(self, sensors, modal_basis)`` once the plant can answer the
   sensor primitives below: it builds the sensor model of `SensorConfig` ``sensors`` in
   the mode shapes ``modal_basis`` (the controller's, for a truth plant).
3. Implement ``state_size``: the length of [θ, q, θ̇, q̇] that ``reset`` takes (q in
   ``modal_basis``).
4. Implement ``reset(state0=None) -> Measurement``: place the arm at ``state0`` (None:
   at rest, undeformed, θ = 0), set ``time`` to 0 and return ``self.measure()``.
5. Implement ``advance(tau, Ts, tip_force=None)``: hold the joint torques ``tau`` (2,)
   [N m] and the payload force ``tip_force`` (Fx, Fy) [N, base frame] over [t, t + Ts)
   exactly (a zero-order hold), then set ``time``; ``self.periods(Ts)`` checks Ts against
   the internal step.  A solver that cannot complete raises `PlantFailure` with its
   reason: the run is then recorded as failed, never lost.
6. Implement ``truth_into(out)``: write the truth vector [θ, q, θ̇, q̇, *TRUTH_EXTRAS]
   into ``out`` (no allocation: the loop calls it every sample).
7. Implement the sensor primitives `SensorModel` reads: ``joint_state()`` → (θ, θ̇),
   ``modal_state()`` → (q, q̇) in ``modal_basis``, ``field_sampler(link, x, derivative)``
   → a callable giving the transverse deflection (or its s-derivatives) at points ``x``
   of link ``link`` (0 or 1), ``tip_positions()`` → (2, 2).
8. Optionally, ``compiled_stepping``: a plant that can step itself in compiled code (the
   reduced plant) returns its kernels there, and the loop runs whole in one call.

The base class gives the rest: ``step`` (advance, then measure), ``measure``,
``measurement_index``, ``truth`` and ``truth_vector``.
"""
from __future__ import annotations

import numpy as np

from ._plant_interface import (TRUTH_EXTRAS, Measurement, TrueState, check_sample_time,
                               true_state_from_vector)
from ._sensors import SensorConfig, SensorModel

__all__ = ["Plant"]


class Plant:
    """Base class of every plant (module docstring: the contract).

    Parameters
    ----------
    sensors : SensorConfig
        What the plant measures.
    modal_basis : (LinkModes, LinkModes)
        The mode shapes its modal coordinates q are expressed in.
    """

    name: str = "plant"
    role: str = "truth"

    def __init__(self, sensors: SensorConfig, modal_basis) -> None:
        self.modal_basis = tuple(modal_basis)
        self.sensors = SensorModel(sensors, self.modal_basis, self)
        self._periods = (None, 0)  # (last Ts, its number of internal steps)
        self.time = 0.0

    # --- what a subclass implements ------------------------------------------------------
    @property
    def state_size(self) -> int:
        raise NotImplementedError

    def reset(self, state0=None) -> Measurement:
        raise NotImplementedError

    def advance(self, tau, Ts: float, tip_force=None) -> None:
        raise NotImplementedError

    def truth_into(self, out: np.ndarray) -> None:
        raise NotImplementedError

    def compiled_stepping(self) -> dict | None:
        """What a compiled loop needs to step this plant itself (None: step it from
        Python, the default)."""
        return None

    # --- what every plant shares ----------------------------------------------------------
    def periods(self, Ts: float) -> int:
        """Internal steps of ``self.h`` in one control period ``Ts`` (checked once per
        distinct Ts: ValueError unless Ts is a whole multiple of the step)."""
        last, steps = self._periods
        if Ts != last:
            steps = check_sample_time(Ts, self.h)
            self._periods = (Ts, steps)
        return steps

    def step(self, tau, Ts: float, tip_force=None) -> Measurement:
        """Hold ``tau`` (and ``tip_force``) for ``Ts`` seconds; return y(t + Ts)
        (`advance`, then `measure`)."""
        self.advance(tau, Ts, tip_force)
        return self.measure()

    def measure(self) -> Measurement:
        """The measurement now."""
        index = self.sensors.truth_index
        if index is not None:  # the measured values are part of the truth vector
            return Measurement(self.time, self.sensors.names, self.truth_vector()[index])
        return self.sensors.measure(self.time)

    def measurement_index(self) -> np.ndarray | None:
        """Where the measurement sits in the truth vector (None: gauges, quantisation or
        the payload position make it more than those values)."""
        return self.sensors.truth_index

    @property
    def truth_size(self) -> int:
        """Length of the truth vector: [θ, q, θ̇, q̇] with q in the modal basis, then
        `TRUTH_EXTRAS`."""
        return 2 * (2 + sum(m.n for m in self.modal_basis)) + len(TRUTH_EXTRAS)

    def truth_vector(self) -> np.ndarray:
        """``[θ, q, θ̇, q̇, *TRUTH_EXTRAS]`` now (a new array)."""
        out = np.empty(self.truth_size)
        self.truth_into(out)
        return out

    def truth(self) -> TrueState:
        """The true state now."""
        return true_state_from_vector(self.time, self.truth_vector())
