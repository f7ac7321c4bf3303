"""Compile the kernels most test files use, once, before the test processes start.

Each test process would otherwise compile for itself every kernel its first tests use
(numba's cache is shared, but two processes that start together both find it empty).
``make test`` runs this in two processes side by side (`tests/conftest.py`), each
compiling one half of `validation.batch.worker.kernel_groups`; the test processes then
load the machine code from the checkout's caches.  Run as ``python warm_kernels.py PART``
(0 or 1).
"""
import sys
from pathlib import Path

#: The scenarios whose kernels the suite uses most: every built-in law on the paper's
#: kinematics, the joints of the lab arm, the exact kinematics, both plants.
SCENARIOS = [
    {"plant": {"kind": "reduced"}, "observer": {"kind": "smo-paper"}},
    {"controller": {"kind": "pbc-idealised"}, "observer": {"kind": "smo-bl"}},
    {"controller": {"kind": "pd"}, "observer": {"kind": "smo-pos"}},
    {"controller": {"kind": "ct"}, "observer": {"kind": "ekf"}},
    {"controller": {"kind": "lqr"}, "observer": {"kind": "ekf-pos"}},
    {"arm": "lab", "observer": {"kind": "smo-paper"}},
    {"plant": {"kind": "reduced", "kinematics": "exact"}, "model": {"kinematics": "exact"},
     "observer": {"kind": "smo-paper"}},
    {"plant": {"kind": "exudyn"}, "observer": {"kind": "smo-paper"}},
]
#: The second process's groups (by label): those of the exact kinematics, which share
#: their kinematics kernels with the exact model's own methods compiled there too, and two
#: baselines; the first process compiles the rest, the joints and the FE plant's loop
#: included (measured, quiet: about 45 s of compile each).
SECOND = ("exact kinematics", "controller lqr", "controller pd")


def model_methods(kinematics: str) -> None:
    """What the physics tests call outside any run: the reduced model's own methods on
    ``kinematics`` (their kernels: `reduced_model.dynamics.entries`), and on the linear
    kinematics the EKF's Jacobian (`controllers._ekf`)."""
    import numpy as np

    from controllers import ExtendedKalmanFilter
    from reduced_model import ArmParameters
    from validation.run.laws import nominal_model
    model = nominal_model(ArmParameters(), None, kinematics)
    Q, Qd = np.full(model.n, 1e-3), np.zeros(model.n)
    model.mass_matrix(Q)
    model.coriolis_matrix(Q, Qd)
    model.acceleration(Q, Qd, np.zeros(model.n_joints))
    model.elastic_force(Q, Qd)
    model.gravity_force(Q)
    model.tip_position(Q)
    model.tip_jacobian(Q)
    if kinematics == "linear":
        ekf = ExtendedKalmanFilter(model, Ts=1e-3)
        ekf.jacobian(np.zeros(2 * model.n), np.zeros(model.n_joints))


def warm(part: int) -> None:
    """Compile part ``part`` (0 or 1): the kernel groups of `SCENARIOS` outside `SECOND`
    and the linear model's methods, or the exact model's methods and then the groups in
    `SECOND`.  The exact methods come first: they need none of the linear-kinematics
    kernels that checking the scenarios compiles, and the first process compiles those
    meanwhile."""
    from validation.batch.worker import kernel_groups
    from validation.run.scenario import scenario_from_mapping
    if part == 1:
        model_methods("exact")
    for label, build in kernel_groups([scenario_from_mapping(s) for s in SCENARIOS]):
        if any(word in label for word in SECOND) == bool(part):
            build()
    if part == 0:
        model_methods("linear")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    warm(int(sys.argv[1]))
