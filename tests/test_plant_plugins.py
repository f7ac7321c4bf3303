"""A user's own plant, in two files outside the package (its module and a TOML naming it):
a `reduced_model.Plant` subclass named by ``plant.kind = "package.module:Class"`` runs in
``run``, ``campaign``, ``verify`` and the report as a truth plant, its role asked, never
its name; bad plug-in plants are one-line errors naming the key."""
import json
import textwrap

import pytest

from cli_testing import flexarm
from conftest import FINE_ARM_PLANT, write_files
from validation.batch.store.folder import ResultStore

SCENARIO = textwrap.dedent('''
    duration = 1.0
    transient = 0.5
    initial_state = "reference"
    [plant]
    kind = "labplants:FineArm"
    role = "truth"
    options = { modes = 3 }
''')

STUDY = textwrap.dedent('''
    name = "lab"
    [scenario]
    duration = 1.0
    transient = 0.5
    initial_state = "reference"
    plant = { kind = "labplants:FineArm", role = "truth", options = { modes = 3 } }
    [[requirement]]
    name = "tracking"
    claim = "tracking"
    [uncertainty]
    "true_params.Mp" = { uniform = [0.0, 0.2] }
''')


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    return write_files(tmp_path_factory.mktemp("plantlab"),
                       {"labplants.py": FINE_ARM_PLANT, "fine.toml": SCENARIO,
                        "study.toml": STUDY})


# slow (15 s: test_a_plugin_plant_runs_in_a_campaign_and_in_verify runs a plug-in plant in make
# test).
@pytest.mark.slow
def test_a_plugin_plant_runs_and_is_reported_as_the_truth(lab):
    run = flexarm(lab, "run", "--config", "fine.toml", "--out", "out")
    assert run.returncode == 0, run.stderr
    (row,) = ResultStore(lab / "out").rows()
    assert row.status == "ok" and row.role == "truth" and row.plant == "labplants:FineArm"
    # Known bad (issue 48, 11): "these are the FE model's numbers on ; --mesh-check ..." and,
    # with --mesh-check, "checks incomplete (against )".
    assert "convergence not checked: the truth plant (labplants:FineArm) declares no " \
           "refinements" in run.stdout
    checked = flexarm(lab, "run", "--config", "fine.toml", "--mesh-check", "--out", "never")
    assert checked.returncode == 2 and "--mesh-check: the truth plant (labplants:FineArm) " \
                                       "declares no refinements" in checked.stderr
    assert not (lab / "never").exists()
    report = flexarm(lab, "report", "out")
    assert report.returncode == 0, report.stderr
    html = (lab / "out" / "report" / "report.html").read_text()
    assert "truth plant (labplants:FineArm)" in html


def test_a_plugin_plant_runs_in_a_campaign_and_in_verify(lab):
    (lab / "sweep.toml").write_text(textwrap.dedent('''
        name = "sweep"
        [scenario]
        duration = 1.0
        transient = 0.5
        plant = { kind = "labplants:FineArm", role = "truth", options = { modes = 3 } }
        [[sweep]]
        grid.seed = [0, 1]
    '''))
    campaign = flexarm(lab, "campaign", "sweep.toml", "--out", "sweep", "--no-progress")
    assert campaign.returncode == 0, campaign.stderr
    assert {r.role for r in ResultStore(lab / "sweep").rows()} == {"truth"}
    verify = flexarm(lab, "verify", "study.toml", "--mode", "estimate", "--samples", "3",
                     "--out", "verify", "--no-progress")
    assert verify.returncode in (0, 1), verify.stderr  # 1: a verdict is missing
    verdict = json.loads((lab / "verify" / "verdict.json").read_text())
    assert verdict["simulations"]["truth"] >= 1  # counted by role, on the plug-in


def test_a_stability_map_of_a_plugin_truth_plant(lab, monkeypatch):
    """A plug-in truth plant is mapped at its own step: its table takes no ``step``
    (known bad, before: every run failed on "plant.step"), and, declaring no
    refinements, it has no refined sequence: one level, the bracket alone."""
    from validation.run.scenario import scenario_from_mapping
    from validation.verdicts import stability
    monkeypatch.syspath_prepend(str(lab))
    monkeypatch.setattr(stability, "GRID", (1e-3, 5e-3))  # multiples of its 0.25 ms step
    monkeypatch.setattr(stability, "DURATION", 0.5)
    s = scenario_from_mapping({"observer": {"kind": "none"}, "plant": {
        "kind": "labplants:FineArm", "role": "truth", "options": {"modes": 3}}})
    (case,) = stability.cases_from_scenarios([s])
    assert case.truth and not case.refines
    (r,), summary = stability.stability_map([case], lab / "map", progress=False,
                                            tolerance=10.0)  # the grid alone
    assert summary.failed == 0 and len(r.tested) == 2 and r.case.level == 0
    assert r.resolved["divergence"].verdict == "" and r.discretisation == ""
    assert r.divergence.largest == 1e-3 and r.divergence.first_bad == 5e-3


@pytest.mark.parametrize("table, message", [
    ('kind = "labplants:Nope"\nrole = "truth"', "plant.kind: module 'labplants' has no 'Nope'"),
    ('kind = "json:JSONDecoder"\nrole = "truth"',
     "plant.kind: json:JSONDecoder is not a reduced_model.Plant"),
    ('kind = "labplants:FineArm"\nrole = "reduced"',
     "plant.role: labplants:FineArm is a 'truth' plant, the scenario says 'reduced'"),
    ('kind = "labplants:FineArm"\nrole = "truth"\noptions = { modez = 3 }',
     "plant.options.modez: not an option of labplants:FineArm (options: modes)"),
    # Known-bad (issue 48, 5): a plug-in that says no role ran as the truth.
    ('kind = "labplants:FineArm"', "plant.role: a plug-in plant must say its role"),
    ('kind = "labplants:NoRole"\nrole = "truth"', "plant.kind: labplants:NoRole declares no role"),
    ('kind = "labplants:Half"\nrole = "truth"',
     "plant.kind: labplants:Half does not implement _advance, _reset"),
])
def test_a_bad_plugin_plant_is_one_line(lab, table, message):
    (lab / "bad.toml").write_text(f"duration = 0.1\n[plant]\n{table}\n")
    proc = flexarm(lab, "run", "--config", "bad.toml", "--out", "bad")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert message in proc.stderr, proc.stderr
    assert not (lab / "bad").exists()


def test_a_subclass_of_the_reduced_plant_with_no_code_is_the_reduced_plant(plugin_lab):
    """Known-bad (issue 44): ``class BarPlant(ReducedPlant)`` with only a docstring was
    refused for its role, then failed on "unexpected keyword argument 'model'".  Now it
    runs, as the plug-in it is, to the built-in reduced plant's metrics exactly."""
    from validation import all_metrics, run_scenario, scenario_from_mapping
    plugin_lab({"barplant.py": 'from reduced_model import ReducedPlant\n\n\n'
                               'class BarPlant(ReducedPlant):\n    """Mine."""\n'})
    base = {"duration": 1.0, "controller": {"kind": "pbc"}, "observer": {"kind": "smo-bl"}}
    own = run_scenario(scenario_from_mapping(
        {**base, "plant": {"kind": "barplant:BarPlant", "role": "reduced"}}))
    builtin = run_scenario(scenario_from_mapping({**base, "plant": {"kind": "reduced"}}))
    assert own.status == builtin.status == "ok"
    assert own.config["plant"]["kind"] == "barplant:BarPlant"
    assert all_metrics(own) == all_metrics(builtin)


def test_verify_judges_a_reduced_plugin_plant_and_its_truth(plugin_lab):
    """Known-bad (issue 48, 7): `flexarm verify` on a plug-in plant of role "reduced"
    failed with "KeyError: 'step'" (the truth plant was made from a step the plug-in's
    table does not have).  Now the reduced runs are the plug-in's own and the truth
    confirmation runs on the default truth plant."""
    lab = plugin_lab({"barplant.py": 'from reduced_model import ReducedPlant\n\n\n'
                                     'class BarPlant(ReducedPlant):\n    """Mine."""\n',
                      "study.toml": STUDY.replace(
                          'plant = { kind = "labplants:FineArm", role = "truth", '
                          'options = { modes = 3 } }',
                          'plant = { kind = "barplant:BarPlant", role = "reduced" }')})
    verify = flexarm(lab, "verify", "study.toml", "--mode", "estimate", "--samples", "3",
                     "--out", "verify", "--no-progress")
    assert verify.returncode in (0, 1), verify.stderr  # 1: a verdict is missing
    verdict = json.loads((lab / "verify" / "verdict.json").read_text())
    assert verdict["simulations"]["reduced"] >= 3, verdict["simulations"]
    rows = ResultStore(lab / "verify").rows()
    assert {r.plant for r in rows if r.role == "reduced"} == {"barplant:BarPlant"}


def test_validity_of_a_plugin_plant_says_what_it_cannot_judge(lab):
    """Known bad (issue 48, 4): `flexarm validity` on a scenario with a plug-in plant
    judged the built-in plants instead, without a word.  It now refuses in one line
    (a plug-in declares no linear model) and says how to judge the built-in arms."""
    proc = flexarm(lab, "validity", "fine.toml", "--out", "v")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "plant.kind: labplants:FineArm is a plug-in plant, which declares no linear " \
           "model" in proc.stderr and "--plant reduced --plant exudyn" in proc.stderr
    assert not (lab / "v").exists()
