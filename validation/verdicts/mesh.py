"""Closed-loop convergence of the truth plant, in space and in time: a truth-plant run is
a result only if the same scenario on a refined mesh, with the other element formulation,
and with a finer integration step gives the same judged values.

The FE model is a discretisation, and so is its time integration.  A closed loop feeds the
mesh's own dynamics back through the sampled controller, so a frequency-domain
convergence study (the open-loop natural frequencies converge at ANCF 4 el/link) does not
prove that a closed-loop run has converged: with no stator inertia at the link-1 tip (the
paper's Table 1 exactly), the motor-2 reaction torque acts on an FE node whose only
rotary inertia is the elements' consistent mass, the joint-2 mobility grows as
(elements)³ (9.9e4, 7.8e5, 6.2e6 at ANCF 4, 8, 16 el/link) and a closed-loop run
describes the mesh, not the arm.  In time, generalised-α at a step near 1 ms damps the
FE modes above ~50 Hz that carry part of the joint mobility: the default arm's PBC,
stable at Ts = 3.16 ms with Exudyn stepping at Ts/3, diverges with a step of Ts/12.

For every truth-plant run a verdict relies on, `check_runs` plans the same scenario three
more times (`refinements`): the same element with twice the elements per link; the other
formulation at a resolution at least as fine (the geometrically exact beam converges
slower: 8× ANCF's elements, GE 32 el/link for ANCF 4 — at 16 it was itself the
unconverged one, a sub-µm modal RMS 15 % off where ANCF 4 and 8 agreed to 0.1 %); and the
run's own mesh with a quarter of its integration step (`STEP_REFINEMENT`).  They are
ordinary runs of the results store (sweep ``mesh-check``): stored, deduplicated, resumed
and verified like any other.  `agrees` is the stated tolerance a judged value must keep
between the checks; `status_agrees` compares runs that did not complete.
"""
from __future__ import annotations

import math

from ..batch.campaign import Campaign, PlannedRun, run_campaign
from ..batch.executor import Runner
from ..batch.store import run_id
from ..run.scenario import scenario_from_mapping, scenario_to_mapping

__all__ = ["MESH_SWEEP", "MESH_RTOL", "MESH_ATOL", "STEP_REFINEMENT", "refinements", "mesh_label", "check_runs",
           "run_checks", "checks_of", "is_check", "agrees", "status_agrees"]

#: The sweep name of the check runs in a results store.
MESH_SWEEP = "mesh-check"
#: Tolerance of a judged value between meshes: |a − b| ≤ MESH_RTOL · max(|a|, |b|) +
#: MESH_ATOL · bound.  On the default arm (PBC + sign SMO, 3 s from the reference) ANCF 4,
#: ANCF 8 and GE 32 give every claim's value within 7 %, except the angle estimate error
#: (1.1 vs 1.3 mrad: the sign observer's chatter); 10 % leaves that margin.  The absolute
#: part (5 % of the claim's bound) keeps a value far inside its bound — 0.2 mrad against
#: 20 mrad — from being judged on its chatter-level digits.  Table 1 moves by 40–70 %.
MESH_RTOL = 0.1
MESH_ATOL = 0.05
#: Element-count ratio of the geometrically exact beam to ANCF in the check (module
#: docstring; open-loop 4th-mode error: GE 16 el/link 0.6 %, ANCF 4 0.04 %).
_GE_PER_ANCF = 8
_MAX_ELEMENTS = 64
#: The time-step check divides the run's integration step by this.
STEP_REFINEMENT = 4


def mesh_label(mesh: dict) -> str:
    """"ANCF 4 el/link", "GE 16 el/link" (or "ANCF 4+8 el/link" if the links differ)."""
    n1, n2 = mesh["elements_per_link"]
    name = "ANCF" if mesh["element"] == "ancf" else "GE"
    return f"{name} {n1 if n1 == n2 else f'{n1}+{n2}'} el/link"


def refinements(config: dict) -> list[tuple[str, dict]]:
    """(label, resolved scenario) of the check runs of a truth-plant run: the same element
    with twice the elements per link, the other element formulation at a comparable
    resolution (meshes beyond 64 el/link are left out), and the run's mesh with its
    integration step divided by `STEP_REFINEMENT` (module docstring)."""
    plant = config["plant"]
    mesh = plant["mesh"]
    n = tuple(mesh["elements_per_link"])
    if mesh["element"] == "ancf":
        other = ("geometrically_exact", tuple(_GE_PER_ANCF * k for k in n))
    else:
        other = ("ancf", tuple(max(1, k // _GE_PER_ANCF) for k in n))
    out = []
    for element, per_link in ((mesh["element"], tuple(2 * k for k in n)), other):
        if max(per_link) > _MAX_ELEMENTS:
            continue
        new_mesh = dict(mesh, element=element, elements_per_link=list(per_link))
        out.append((mesh_label(new_mesh), dict(config, plant=dict(plant, mesh=new_mesh))))
    # one label for every run (a column of the report's tables): the step is the run's own
    step = plant["step"] / STEP_REFINEMENT
    out.append((f"{mesh_label(mesh)}, step/{STEP_REFINEMENT}",
                dict(config, plant=dict(plant, step=step))))
    return out


def is_check(row) -> bool:
    """Whether a stored run is a mesh-check run (not a result of its own)."""
    return getattr(row, "sweep", "") == MESH_SWEEP


def check_runs(rows) -> list[PlannedRun]:
    """The check runs of every truth-plant run among ``rows`` (stored runs) that is not a
    check itself."""
    planned: dict[str, PlannedRun] = {}
    for row in rows:
        if row.config["plant"]["kind"] != "exudyn" or is_check(row):
            continue
        for label, config in refinements(row.config):
            scenario = scenario_from_mapping(config)
            rid = run_id(scenario_to_mapping(scenario))
            planned.setdefault(rid, PlannedRun(rid, scenario, MESH_SWEEP,
                                               {"mesh": label, "of": row.run_id}))
    return list(planned.values())


def run_checks(rows, out, *, runner: Runner | None = None, progress: bool = True):
    """Run the check runs of ``rows`` into the results folder ``out`` (what it holds
    already is skipped); returns the campaign summary."""
    campaign = Campaign(name=MESH_SWEEP, base={}, sweeps=(),
                        description="closed-loop mesh convergence of the truth-plant runs")
    return run_campaign(campaign, out, runner=runner, progress=progress,
                        only=check_runs(rows))


def checks_of(row, rows_by_id: dict) -> dict[str, object] | None:
    """{mesh label: stored check run or None (not run)} of a truth-plant run; None for a
    reduced-plant run."""
    if row.config["plant"]["kind"] != "exudyn":
        return None
    out = {}
    for label, config in refinements(row.config):
        rid = run_id(scenario_to_mapping(scenario_from_mapping(config)))
        out[label] = rows_by_id.get(rid)
    return out


def agrees(a: float, b: float, bound: float) -> bool:
    """Whether two values of one judged quantity on two meshes agree within the stated
    tolerance (`MESH_RTOL`, `MESH_ATOL`); two infinities (never converged) agree, NaN
    (not applicable) agrees only with NaN."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= MESH_RTOL * max(abs(a), abs(b)) + MESH_ATOL * abs(bound)


def status_agrees(a, b) -> bool:
    """Two runs that did not both complete agree only if both diverged (or both failed):
    then "diverged" is the result on every mesh."""
    return a.status == b.status
