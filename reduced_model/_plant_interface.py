"""What plants and the closed loop exchange: measurements, true states, the truth vector's
layout, the failure a plant reports, and the sample-time check (the contract itself is
`reduced_model._plant_base.Plant`)."""
from __future__ import annotations

import numpy as np

__all__ = ["Measurement", "TrueState", "PlantFailure", "check_sample_time",
           "TRUTH_EXTRAS", "MOTOR_OUTPUTS", "true_state_from_vector", "coordinate_names",
           "output_names"]

#: After the state [θ, q, θ̇, q̇], `truth_vector()` holds these, in this order.
TRUTH_EXTRAS = ("tip1_x", "tip1_y", "tip2_x", "tip2_y", "tip_defl1", "tip_defl2",
                "proj_res1", "proj_res2", "motor1", "motor2", "motor1_dot", "motor2_dot")
#: What the encoders read (a drive's rotor, else θ) and its rate: the last of both.
MOTOR_OUTPUTS = TRUTH_EXTRAS[-4:]


def coordinate_names(modes_per_link: tuple[int, int]) -> tuple[str, ...]:
    """The names every model, plant, measurement and linear model gives its coordinates.

    Parameters
    ----------
    modes_per_link : (int, int)
        Assumed modes of link 1 and link 2.

    Returns
    -------
    tuple of str
        ``theta1``, ``theta2``, then ``q<i><j>`` (link i, mode j).

    Examples
    --------
    >>> from reduced_model import coordinate_names
    >>> coordinate_names((2, 1))
    ('theta1', 'theta2', 'q11', 'q12', 'q21')
    """
    return ("theta1", "theta2", *(f"q{i + 1}{j + 1}" for i, n in enumerate(modes_per_link)
                                  for j in range(n)))


def output_names(modes_per_link: tuple[int, int]) -> tuple[str, ...]:
    """The outputs of both plants' linear models.

    Parameters
    ----------
    modes_per_link : (int, int)
        Assumed modes of link 1 and link 2 of the basis q is expressed in.

    Returns
    -------
    tuple of str
        The coordinates (`coordinate_names`), their rates (``..._dot``), then
        ``tip_defl1``, ``tip_defl2``, then `MOTOR_OUTPUTS` (what the encoders read).
    """
    coords = coordinate_names(modes_per_link)
    return (coords + tuple(f"{c}_dot" for c in coords) + ("tip_defl1", "tip_defl2")
            + MOTOR_OUTPUTS)


class PlantFailure(RuntimeError):
    """The plant's solver could not complete a step (the message says why)."""


class Measurement:
    """A named measurement vector at ``time`` [s] (radians, metres, SI).

    A plain slotted class rather than a frozen dataclass: plants create one per control
    period, and this is ~3× cheaper to construct.  Treat it as read-only.

    Parameters
    ----------
    time : float
        When it was measured [s].
    names : tuple of str
        The signal names (`measured_names`: ``theta1``, ``q11``, ``theta1_dot`` …).
    values : ndarray
        One value per name, SI units.
    """

    __slots__ = ("time", "names", "values")

    def __init__(self, time: float, names: tuple[str, ...], values: np.ndarray) -> None:
        self.time = time
        self.names = names
        self.values = values

    def __repr__(self) -> str:
        pairs = ", ".join(f"{k}={v:.6g}" for k, v in zip(self.names, self.values))
        return f"Measurement(t={self.time:.6g}, {pairs})"

    def __getitem__(self, name: str) -> float:
        try:
            return float(self.values[self.names.index(name)])
        except ValueError:
            raise KeyError(f"no signal {name!r} in measurement {self.names}") from None


class TrueState:
    """What the plant really does, in the reduced model's coordinates (read-only by
    convention; a slotted class because the closed loop reads one per sample).

    Parameters
    ----------
    time : float
        When [s].
    theta, theta_dot : ndarray (2,)
        Joint angles [rad] and rates [rad/s]; θ2 relative to the link-1 tip tangent.
    q, q_dot : ndarray (n1 + n2,)
        Modal coordinates of the plant's modal basis [m] and their rates.
    tip_positions : ndarray (2, 2)
        (x, y) [m] of the link-1 tip and the link-2 tip (payload).
    tip_deflections : ndarray (2,)
        w_i(L_i) [m] in each link's clamped root frame.
    projection_residual : ndarray (2,)
        Per link, the mass-weighted RMS over the link [m] of the deflection the modes
        cannot represent (0 for the reduced plant).
    motor_angles, motor_rates : ndarray (2,), optional
        The motors' angles [rad] and rates [rad/s] reflected to the link side, what the
        encoders read: the rotors of an arm with drives (`ArmParameters.gear_stiffness1`),
        θ and θ̇ themselves where a joint has none (the default).
    x : ndarray, optional
        The reduced model's state vector [θ, q, θ̇, q̇] (default: made from the others).
    """

    __slots__ = ("time", "theta", "theta_dot", "q", "q_dot", "tip_positions",
                 "tip_deflections", "projection_residual", "motor_angles", "motor_rates", "x")

    def __init__(self, *, time, theta, theta_dot, q, q_dot, tip_positions, tip_deflections,
                 projection_residual, motor_angles=None, motor_rates=None, x=None) -> None:
        self.time, self.theta, self.theta_dot = time, theta, theta_dot
        self.q, self.q_dot = q, q_dot
        self.tip_positions, self.tip_deflections = tip_positions, tip_deflections
        self.projection_residual = projection_residual
        self.motor_angles = theta if motor_angles is None else motor_angles
        self.motor_rates = theta_dot if motor_rates is None else motor_rates
        self.x = np.concatenate([theta, q, theta_dot, q_dot]) if x is None else x

    def __repr__(self) -> str:
        return (f"TrueState(t={self.time:.6g}, theta={self.theta}, q={self.q}, "
                f"tip_deflections={self.tip_deflections})")


def true_state_from_vector(time: float, v: np.ndarray) -> TrueState:
    """`TrueState` of a `truth_vector` (the state x then TRUTH_EXTRAS)."""
    m = (len(v) - len(TRUTH_EXTRAS)) // 2  # number of coordinates n
    x, extras = v[:2 * m], v[2 * m:]
    return TrueState(time=time, theta=x[:2], theta_dot=x[m:m + 2], q=x[2:m], q_dot=x[m + 2:],
                     tip_positions=extras[:4].reshape(2, 2), tip_deflections=extras[4:6],
                     projection_residual=extras[6:8], motor_angles=extras[8:10],
                     motor_rates=extras[10:12], x=x)


def check_sample_time(Ts: float, h: float) -> int:
    """Number of internal steps h in one control period Ts.

    Parameters
    ----------
    Ts : float
        The control period [s].
    h : float
        The plant's internal step [s].

    Returns
    -------
    int
        Ts / h.

    Raises
    ------
    ValueError
        Unless Ts is a positive whole multiple of h (to 1e-9 relative).

    Examples
    --------
    >>> from reduced_model import check_sample_time
    >>> check_sample_time(1e-3, 2.5e-4)
    4
    """
    if not (np.isfinite(Ts) and Ts > 0.0):
        raise ValueError(f"Ts must be a positive number of seconds, got {Ts!r}")
    n = int(round(Ts / h))
    if n < 1 or abs(n * h - Ts) > 1e-9 * Ts:
        raise ValueError(f"Ts={Ts!r} s is not a whole multiple of the plant step {h!r} s")
    return n
