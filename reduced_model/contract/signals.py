"""What plants and the closed loop exchange: measurements, true states, the truth vector's
layout, the failure a plant reports, and the sample-time check (the contract itself is
`reduced_model.contract.plant.Plant`)."""
from __future__ import annotations

import numpy as np

__all__ = ["Measurement", "TrueState", "PlantFailure", "check_sample_time", "truth_extras",
           "motor_outputs", "true_state_from_vector", "coordinate_names", "output_names"]


def truth_extras(links: int) -> tuple[str, ...]:
    """What `truth_vector()` holds after the state [θ, q, θ̇, q̇], in this order, for an arm
    of ``links`` links: each tip's position, each tip's deflection, each link's modal
    projection residual, what each encoder reads and its rate (`motor_outputs`).

    Parameters
    ----------
    links : int
        The arm's links N.

    Returns
    -------
    tuple of str
        6N names.

    Examples
    --------
    >>> from reduced_model import truth_extras
    >>> truth_extras(1)
    ('tip1_x', 'tip1_y', 'tip_defl1', 'proj_res1', 'motor1', 'motor1_dot')
    """
    ks = range(1, links + 1)
    return (tuple(name for k in ks for name in (f"tip{k}_x", f"tip{k}_y"))
            + tuple(f"tip_defl{k}" for k in ks) + tuple(f"proj_res{k}" for k in ks)
            + motor_outputs(links))


def motor_outputs(links: int) -> tuple[str, ...]:
    """What the encoders read (a drive's rotor, else θ), then its rate: the last 2N of
    `truth_extras`.

    Parameters
    ----------
    links : int
        The arm's links N.

    Returns
    -------
    tuple of str
        ``motor1`` … ``motorN``, then ``motor1_dot`` … ``motorN_dot``.
    """
    ks = range(1, links + 1)
    return tuple(f"motor{k}" for k in ks) + tuple(f"motor{k}_dot" for k in ks)


def coordinate_names(modes_per_link: tuple[int, ...]) -> tuple[str, ...]:
    """The names every model, plant, measurement and linear model gives its coordinates.

    Parameters
    ----------
    modes_per_link : tuple of int
        Assumed modes of each link (0: rigid).

    Returns
    -------
    tuple of str
        ``theta1`` … ``thetaN``, then ``q<i><j>`` (link i, mode j).

    Examples
    --------
    >>> from reduced_model import coordinate_names
    >>> coordinate_names((2, 1))
    ('theta1', 'theta2', 'q11', 'q12', 'q21')
    """
    return (*(f"theta{i + 1}" for i in range(len(modes_per_link))),
            *(f"q{i + 1}{j + 1}" for i, n in enumerate(modes_per_link) for j in range(n)))


def output_names(modes_per_link: tuple[int, ...]) -> tuple[str, ...]:
    """The outputs of both plants' linear models.

    Parameters
    ----------
    modes_per_link : tuple of int
        Assumed modes of each link of the basis q is expressed in.

    Returns
    -------
    tuple of str
        The coordinates (`coordinate_names`), their rates (``..._dot``), then each tip's
        deflection ``tip_defl<i>``, then `motor_outputs` (what the encoders read).
    """
    coords = coordinate_names(modes_per_link)
    links = len(modes_per_link)
    return (coords + tuple(f"{c}_dot" for c in coords)
            + tuple(f"tip_defl{k}" for k in range(1, links + 1)) + motor_outputs(links))


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
    theta, theta_dot : ndarray (N,)
        Joint angles [rad] and rates [rad/s]; θ_i relative to link i−1's tip tangent.
    q, q_dot : ndarray (Σ n_i,)
        Modal coordinates of the plant's modal basis [m] and their rates.
    tip_positions : ndarray (N, 2)
        (x, y) [m] of each link's tip (the last: the payload).
    tip_deflections : ndarray (N,)
        w_i(L_i) [m] in each link's clamped root frame.
    projection_residual : ndarray (N,)
        Per link, the mass-weighted RMS over the link [m] of the deflection the modes
        cannot represent (0 for the reduced plant).
    motor_angles, motor_rates : ndarray (N,), optional
        The motors' angles [rad] and rates [rad/s] reflected to the link side, what the
        encoders read: the rotors of joints with drives (`Joint.gear_stiffness`), θ and θ̇
        themselves where a joint has none (the default).
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


def true_state_from_vector(time: float, v: np.ndarray, links: int) -> TrueState:
    """`TrueState` of a `truth_vector` of an arm of ``links`` links (the state x then
    `truth_extras`)."""
    N = links
    m = (len(v) - 6 * N) // 2  # number of coordinates n
    x, extras = v[:2 * m], v[2 * m:]
    return TrueState(time=time, theta=x[:N], theta_dot=x[m:m + N], q=x[N:m], q_dot=x[m + N:],
                     tip_positions=extras[:2 * N].reshape(N, 2),
                     tip_deflections=extras[2 * N:3 * N], projection_residual=extras[3 * N:4 * N],
                     motor_angles=extras[4 * N:5 * N], motor_rates=extras[5 * N:6 * N], x=x)


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
