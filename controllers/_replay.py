"""Open-loop replay of recorded joint torques: the input of a calibration experiment
reproduced sample for sample (`validation.verdicts.calibration`).

The torques are read from a ``.npy`` file (float64, shape (samples, joints), N m; no pickle)
whose SHA-256 the options name, so a scenario that replays them is identified by their
content: its run id changes with the data, and a file changed after the fact is refused
instead of silently replayed.  The torque at t_k = k·Ts is row k, held over
[t_k, t_k+1) like any controller's output; past the last row the torque is NaN, so the
loop ends the run ("torque not finite") instead of inventing an input.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit

from reduced_model import ArmModel

from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import control_period

__all__ = ["TorqueReplay", "file_sha256"]


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, hex."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class TorqueReplay:
    """τ_k = the recorded torques of row k (module docstring); ignores the state.

    Parameters
    ----------
    model : ArmModel
        The nominal model (unused: the interface's first argument).
    Ts : float
        The control period [s] (the scenario's; row k is applied at t = k·Ts).
    file : str
        A ``.npy`` file of shape (samples, joints) [N m]: one column per joint of the
        model's arm.
    sha256 : str
        The file's SHA-256 (hex): a file with other content is refused.
    """

    name = "replay"

    def __init__(self, model: ArmModel, *, Ts: float, file: str, sha256: str) -> None:
        path = Path(file)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ValueError(f"file {file}: cannot read ({exc.strerror or exc})") from None
        if hashlib.sha256(data).hexdigest() != sha256:
            raise ValueError(f"file {file}: its SHA-256 is not the one given (the torques "
                             "changed after the scenario was written)")
        torques = np.load(path, allow_pickle=False)
        joints = model.n_joints
        if torques.ndim != 2 or torques.shape[1] != joints or not np.all(np.isfinite(torques)):
            raise ValueError(f"file {file}: expected finite torques of shape (samples, "
                             f"{joints}), got shape {torques.shape}")
        self.torques = np.ascontiguousarray(torques, dtype=np.float64)
        self.model, self.Ts = model, control_period(Ts)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        k = int(round(t / self.Ts))
        if k >= len(self.torques):
            return np.full(self.torques.shape[1], np.nan)
        return self.torques[k].copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): ints = [rows, joints], reals =
        [1/Ts, τ rows...]."""
        return CompiledLaw.of(replay_kernel, CONTROLLER_SIGNATURE, self.model,
                              ints=list(self.torques.shape),
                              reals=np.concatenate([[1.0 / self.Ts], self.torques.ravel()]))


@njit(cache=True)
def replay_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`TorqueReplay` compiled: ints = [rows, joints], reals = [1/Ts, τ1_0, τ2_0, …,
    τ1_1, …]."""
    k = int(t * reals[0] + 0.5)
    joints = ints[1]
    for j in range(joints):
        tau[j] = np.nan if k >= ints[0] else reals[1 + joints * k + j]
    return joints
