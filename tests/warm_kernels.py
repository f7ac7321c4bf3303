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
#: The second process's groups (by label): those of the joints and the exact kinematics,
#: the larger half by `validation.batch.compiling.REFERENCE_SECONDS`; the first process
#: compiles the rest, the FE plant's loop included.
SECOND = ("joints", "exact kinematics")


def parts():
    """The kernel groups of `SCENARIOS`, split in two ([first, second])."""
    from validation.batch.worker import kernel_groups
    from validation.run.scenario import scenario_from_mapping
    groups = kernel_groups([scenario_from_mapping(s) for s in SCENARIOS])
    second = [g for g in groups if any(word in g[0] for word in SECOND)]
    return [[g for g in groups if g not in second], second]


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    for _, build in parts()[int(sys.argv[1])]:
        build()
