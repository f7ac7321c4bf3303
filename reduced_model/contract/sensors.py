"""What a plant measures: encoders, strain-gauge-derived modal coordinates, tip position.

Shared by both plants so that a scenario's sensor set means the same on each.  A plant
provides four primitives — ``joint_state()`` → (θ, θ̇), ``modal_state()`` → (q, q̇) in
its measurement basis, ``field_sampler(link, x, derivative)`` → a callable returning the
transverse deflection (or its s-derivatives) at points ``x`` of link ``link`` (from 0),
and ``tip_positions()`` → (N, 2) — and `SensorModel` turns them into a `Measurement`.
Noise is added by the closed loop, not here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm import FieldError
from ..shapes import LinkModes
from .signals import Measurement, coordinate_names, truth_extras

__all__ = ["SensorConfig", "SensorModel", "STRAIN_QUANTITIES", "measured_names"]

STRAIN_QUANTITIES = {"deflection": 0, "curvature": 2}


@dataclass(frozen=True)
class SensorConfig:
    """The sensor set of a plant.

    Parameters
    ----------
    encoder_resolution : float
        Encoder quantisation step [rad] (0: continuous).  θ is rounded to it.
    strain_gauges : tuple of (float, ...), or None
        Gauge positions [m from the root] on each link (none on a rigid link).  None: the
        modal coordinates are read directly (the paper's assumption); otherwise q is the
        least-squares fit of the modes to the gauge readings (needs ≥ as many gauges as
        modes on each link).
    strain_quantity : {"curvature", "deflection"}
        What a gauge reads: curvature w'' (a strain gauge; surface strain = −c w'') or
        deflection w (e.g. an optical sensor).
    modal : bool
        Measure the modal coordinates at all (False: encoders only).
    rates : bool
        Append θ̇ and q̇ (q̇ from the plant's modal state, not differentiated gauges).
    tip_position : bool
        Append the payload's (x, y) [m].
    """

    encoder_resolution: float = 0.0
    strain_gauges: tuple[tuple[float, ...], ...] | None = None
    strain_quantity: str = "curvature"
    modal: bool = True
    rates: bool = False
    tip_position: bool = False

    def __post_init__(self) -> None:
        res = self.encoder_resolution
        if isinstance(res, bool) or not isinstance(res, (int, float)) or not np.isfinite(res) \
                or res < 0:
            raise FieldError("sensors", "encoder_resolution", f"must be a number >= 0, got {res!r}")
        if self.strain_quantity not in STRAIN_QUANTITIES:
            raise FieldError("sensors", "strain_quantity", f"must be one of "
                             f"{sorted(STRAIN_QUANTITIES)}, got {self.strain_quantity!r}")
        if self.strain_gauges is not None:
            gauges = self.strain_gauges
            if not isinstance(gauges, (tuple, list)) or not gauges or not all(
                    isinstance(g, (tuple, list)) for g in gauges):
                raise FieldError("sensors", "strain_gauges", "must be one list of positions "
                                 f"per link, got {gauges!r}")
            object.__setattr__(self, "strain_gauges",
                               tuple(tuple(float(x) for x in g) for g in gauges))


def measured_names(modes_per_link: tuple[int, ...], *, modal: bool, rates: bool,
                   tip_position: bool) -> tuple[str, ...]:
    """The names of a measurement, in its order.

    Parameters
    ----------
    modes_per_link : tuple of int
        Modes of each link of the basis q is expressed in.
    modal : bool
        Whether the modal coordinates are measured.
    rates : bool
        Whether the rates are.
    tip_position : bool
        Whether the payload position is.

    Returns
    -------
    tuple of str
        θ, then q (``modal``), then their rates (``rates``), then ``tip_x``, ``tip_y``.
    """
    coords = coordinate_names(modes_per_link)
    names = coords if modal else coords[:len(modes_per_link)]
    if rates:
        names += tuple(f"{n}_dot" for n in names)
    return names + (("tip_x", "tip_y") if tip_position else ())


class SensorModel:
    """Builds the `Measurement` of a plant from a `SensorConfig`.

    Parameters
    ----------
    config : SensorConfig
    modes : tuple of LinkModes
        The basis the modal coordinates are expressed in (the plant's measurement basis).
    plant
        Provides the primitives listed in the module docstring, and its
        ``encoder_side``: what each encoder reads, "link" (θ) or "motor" (the rotor of a
        drive, reflected to the link side: its reading still named ``theta<i>``, what a
        law is fed as θ).

    Attributes
    ----------
    encoder_side : tuple of str
        "link" or "motor" for each joint's encoder (and its rate).
    """

    def __init__(self, config: SensorConfig, modes: tuple[LinkModes, ...], plant) -> None:
        self.config = config
        self._plant = plant
        self.encoder_side = tuple(plant.encoder_side)
        modes_per_link = tuple(m.n for m in modes)
        self.names = names = measured_names(modes_per_link, modal=config.modal,
                                            rates=config.rates,
                                            tip_position=config.tip_position)
        states = coordinate_names(modes_per_link)
        states += tuple(f"{n}_dot" for n in states)
        self._extras = truth_extras(len(modes))
        layout = list(states + self._extras)
        for i, side in enumerate(self.encoder_side):  # a motor-side encoder reads the rotor
            if side == "motor":
                for suffix in ("", "_dot"):
                    layout[layout.index(f"theta{i + 1}{suffix}")] = None
                    layout[layout.index(f"motor{i + 1}{suffix}")] = f"theta{i + 1}{suffix}"
        direct = (config.strain_gauges is None or not config.modal) and \
            config.encoder_resolution == 0 and not config.tip_position
        #: Where each measured value sits in the plant's truth vector, when the measurement
        #: is exactly those values (no gauges, no quantisation, no payload position).
        self.truth_index = (np.array([layout.index(m) for m in names], dtype=np.int64)
                            if direct else None)
        self._samplers, self._fits = [], []
        if config.modal and config.strain_gauges is not None:
            k = STRAIN_QUANTITIES[config.strain_quantity]
            if len(config.strain_gauges) != len(modes):
                raise ValueError(f"sensors.strain_gauges: one list per link ({len(modes)}), "
                                 f"got {len(config.strain_gauges)}")
            for link, (x, m) in enumerate(zip(config.strain_gauges, modes)):
                if m.n == 0:
                    if len(x):
                        raise ValueError(f"sensors.strain_gauges: link {link + 1} is rigid: "
                                         "it takes no gauges")
                    continue
                x = np.asarray(x, dtype=float)
                if len(x) < m.n:
                    raise ValueError(f"sensors.strain_gauges: link {link + 1} has {len(x)} "
                                     f"gauge(s) for {m.n} modes; need at least {m.n}")
                if np.any(x < 0) or np.any(x > m.L):
                    raise ValueError(f"sensors.strain_gauges: link {link + 1} positions must "
                                     f"lie in [0, {m.L}] m, got {x.tolist()}")
                basis = m.evaluate(x, k).T  # (gauges, modes)
                if np.linalg.matrix_rank(basis) < m.n:
                    raise ValueError(f"sensors.strain_gauges: link {link + 1} gauges at "
                                     f"{x.tolist()} cannot distinguish its {m.n} modes")
                self._fits.append(np.linalg.pinv(basis))
                self._samplers.append(plant.field_sampler(link, x, k))

    def modal_positions(self) -> np.ndarray:
        """q from the gauges (least squares), or the plant's modal state without gauges."""
        if not self._fits:
            return self._plant.modal_state()[0]
        return np.concatenate([fit @ sample() for fit, sample in zip(self._fits, self._samplers)])

    def measure(self, time: float) -> Measurement:
        cfg = self.config
        theta, theta_dot = self._plant.joint_state()
        if "motor" in self.encoder_side:
            extras = self._extras
            motor = self._plant.truth_vector()[-len(extras):]
            N = len(self.encoder_side)
            for i, side in enumerate(self.encoder_side):
                if side == "motor":
                    k = extras.index(f"motor{i + 1}")
                    theta[i], theta_dot[i] = motor[k], motor[k + N]
        res = cfg.encoder_resolution
        parts = [np.round(theta / res) * res if res > 0 else theta]
        if cfg.modal:
            parts.append(self.modal_positions())
        if cfg.rates:
            parts.append(theta_dot)
            if cfg.modal:
                parts.append(self._plant.modal_state()[1])
        if cfg.tip_position:
            parts.append(self._plant.tip_positions()[-1])
        return Measurement(time, self.names, np.concatenate(parts))
