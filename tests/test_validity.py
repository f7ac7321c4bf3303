"""`flexarm validity`: bad input refused in one line; the analysis written as data, tables
and figures; the report's validity section drawn from what was stored."""
import json
import math
from pathlib import Path

import pytest

from validation.batch.campaign import campaign_from_mapping

from validation.batch.queue import run_campaign
from validation.cli import main
from validation.report.report import write_report
from validation.report.verdict_tables import write_validity
from validation.verdicts.validity_file import channels, load_validity


@pytest.mark.parametrize("argv, text", [
    (["validity", "{tmp}/missing.toml"], "missing.toml"),
    (["validity", "{tmp}/bad.toml"], "duration"),
    (["validity", "{tmp}/ok.toml", "--stability", "{tmp}"], "--stability"),
    (["validity", "{tmp}/ok.toml", "--arm", "paper"], "arm: 'paper' is not a shipped arm"),
])
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, argv, text):
    (tmp_path / "bad.toml").write_text("duration = -1.0\n")
    (tmp_path / "ok.toml").write_text("duration = 5.0\n")
    out = tmp_path / "out"
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv] + ["--out", str(out)]
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own errors exit here, with the same rules
        status = exc.code
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flexarm: error:") and text in err[0]
    assert not out.exists()


def synthetic_analysis() -> dict:
    """A validity analysis as `validity_analysis` returns it, with made-up numbers."""
    f = [0.1, 1.0, 10.0, 100.0]
    curve = {f"{i}->{o}": [1.0, 0.1, 0.01, 0.001] for i, o in channels((2, 2))}
    arm = {"arm": "default", "Ts": 1e-3, "modes": [2, 2], "law": "mylab:MyPD",
           "truth": "truth plant (Exudyn), ANCF 4 el/link",
           "left_out": ["joint 1 dry friction (Coulomb 0.3 N m, breakaway 0.4 N m)"],
           "frequencies_hz": f,
           "responses": [{"theta2": t, "reduced": curve, "fe": curve} for t in (0.0, 1.0, 2.0, 3.0)],
           "gaps": [{"theta2": t, "theta": 0.1, "theta_peak_hz": 3.0, "tip": 0.2,
                     "tip_peak_hz": 30.0, "loop": math.nan, "loop_peak_hz": math.nan}
                    for t in (0.0, 1.0)]}
    case = {"case": "pbc", "plant": "exudyn", "arm": "default", "predicted_s": 2.7e-3,
            "predicted_theta2": 0.0, "note": "FE linearisation, ancf 4+4 elements",
            "mesh": "truth plant (Exudyn), ANCF 4 el/link", "predicted_fine_s": 2.71e-3,
            "mesh_fine": "truth plant (Exudyn), ANCF 8 el/link", "truth": True,
            "certified_s": 7e-4, "certificate": [{"Ts": 7e-4, "nu_gap": 0.47, "margin": 0.51,
                                                  "certified": True}],
            "largest_stable_s": 3.5e-3, "first_unstable_s": 4e-3, "limit_low_s": 3.4e-3,
            "limit_high_s": 4e-3, "limit_verdict": "converged", "in_bracket": "no",
            "sound": "yes", "conservatism": 0.2, "evidence": "truth plant with step Ts/200: "
                                                               "0.97×: ok, 1.05×: diverged",
            "seconds": 1.0}
    return {"arms": [arm], "cases": [case], "timings": {"everything [s]": 1.0},
            "stability": "", "certify_periods": [7e-4], "points": 5}


def test_written_analysis_reads_back_and_is_reported(tmp_path):
    out = tmp_path / "res"
    spec = {"name": "v", "scenario": {"duration": 0.2, "transient": 0.1}}
    run_campaign(campaign_from_mapping(spec), out, progress=False)
    data = synthetic_analysis()
    (out / "validity").mkdir()  # as `flexarm validity` makes it (own_folder)
    text = write_validity(data, out / "validity")
    assert "| pbc | exudyn | default | 2.7 | truth plant (Exudyn), ANCF 4 el/link | 2.71 | 0.7 | 3.5 | 4 | (3.4, 4] converged | no | yes | 0.2 |" \
        in text
    assert "δν mylab:MyPD loop at Ts" in text  # the scenario's own controller, named
    assert ("Not in the linear models of the default arm" in text  # said, not dropped
            and "joint 1 dry friction (Coulomb 0.3 N m" in text)
    back = load_validity(out / "validity")
    assert back["cases"][0]["certified_s"] == 7e-4
    assert math.isnan(back["arms"][0]["gaps"][0]["loop"])  # not computed stays empty
    assert sorted(p.name for p in (out / "validity" / "figures").iterdir()) == \
        ["validity00.png", "validity01.png", "validity02.png"]
    html_path, md_path = write_report(out, animate=False, progress=False)
    html, md = html_path.read_text(), md_path.read_text()
    for page in (html, md):
        assert "predicted, certified, measured" in page
        assert "ν-gap between the reduced model and the FE arm over θ₂" in page
        assert "0.97×: ok, 1.05×: diverged" in page


@pytest.mark.slow
def test_validity_of_a_scenario_end_to_end(tmp_path, capsys):
    """The PBC on the reduced plant of the default arm: the whole analysis, written."""
    (tmp_path / "s.toml").write_text('[controller]\nkind = "pbc"\n')
    out = tmp_path / "out"
    assert main(["validity", str(tmp_path / "s.toml"), "--arm", "default", "--plant",
                 "reduced", "--out", str(out), "--no-progress"]) == 0
    data = json.loads((out / "validity" / "validity.json").read_text())
    (row,) = data["cases"]
    assert row["predicted_s"] == pytest.approx(3.051e-3, rel=1e-3)
    assert 0 < row["certified_s"] < row["predicted_s"]
    gaps = data["arms"][0]["gaps"]
    assert len(gaps) == 7 and all(0 < g["theta"] < 1 for g in gaps)
    assert data["arms"][0]["law"] == "pbc"
    # The terminal gets a summary: no markdown table, no image link (they are in the files).
    printed = capsys.readouterr().out
    assert "|" not in printed and "![" not in printed
    assert "pbc · reduced · default: predicted 3.05 ms" in printed
    assert len(printed.splitlines()) == 4


def test_validity_finds_the_stability_map_its_file_was_measured_into(tmp_path, monkeypatch):
    """Issue 47: `flexarm validity campaigns/paper.toml` showed "measured —" for every
    case although `make demo` had just stored results/paper/stability.  Without
    --stability it now takes the map `flexarm stability FILE` (results/stability-STEM)
    or `reproduce-paper`/`campaign` (results/NAME/stability) stored; with none, none."""
    import argparse
    from validation.cli.verdicts import _stability_folder
    from validation.verdicts import stability
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(stability, "GRID", (1e-3,))
    monkeypatch.setattr(stability, "DURATION", 0.2)
    (tmp_path / "s.toml").write_text('[controller]\nkind = "pd"\n')
    args = argparse.Namespace(file="s.toml", stability=None)
    out = Path("results") / "validity-s"
    assert _stability_folder(args, out) is None  # known-bad: nothing measured yet
    assert main(["stability", "s.toml", "--plant", "reduced", "--arm", "default",
                 "--workers", "1", "--no-progress"]) == 0
    assert _stability_folder(args, out) == Path("results") / "stability-s"
    assert main(["stability", "s.toml", "--plant", "reduced", "--arm", "default",
                 "--workers", "1", "--no-progress", "--out", "results/s/stability"]) == 0
    assert _stability_folder(args, out) == Path("results") / "s" / "stability"


def test_the_validity_map_of_an_arm_with_drives_warns_of_nothing():
    """Known-bad before: the lab arm's FE model has a rigid mode per rotor (1e-8..1e-4 Hz
    from its eigen-solver), which the map paired with the reduced model's bending modes
    (relative errors of 1e6-1e10 %, and "RuntimeWarning: divide by zero" printed by
    `reproduce-paper --lab`); the map now compares the bending modes above RIGID_HZ."""
    import warnings
    from validation.report.verdict_figures import validity_map
    from reduced_model import named_arm
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        figure = validity_map(named_arm("lab"), (2, 2), "the lab arm")
    assert figure.startswith(b"\x89PNG")


# --- the three-link arm: N×N transfer matrices ---------------------------------------------------
def _three_link_theta_gap(stiffness_factor: float, theta=(0.0, 0.0, 0.0)):
    """δν of τ → θ (3×3) between the three-link arm's exact-kinematics reduced model, with
    its flexible links' EI scaled by ``stiffness_factor``, and its FE arm (ANCF 4 el/link)
    linearised at ``theta``."""
    import dataclasses

    from plant_exudyn import linear_model
    from reduced_model import ArmModel, named_arm, reduced_linear_model
    from validation.verdicts.nugap import gap_detail
    arm = named_arm("three-link")
    wrong = dataclasses.replace(arm, links=tuple(
        link if link.rigid else dataclasses.replace(
            link, bending_stiffness=stiffness_factor * link.bending_stiffness)
        for link in arm.links))
    encoders = ["motor1", "motor2", "motor3"]
    fe = linear_model(arm, theta=theta, model=ArmModel(arm, kinematics="exact"))
    reduced = reduced_linear_model(ArmModel(wrong, kinematics="exact"), theta=theta)
    return gap_detail(reduced[encoders, :], fe[encoders, :]).value


@pytest.mark.parametrize("theta, bound", [((0.0, 0.0, 0.0), 0.1), ((0.0, 1.0, 0.5), 0.1)])
def test_the_three_link_reduced_model_is_close_to_its_fe_arm(theta, bound):
    """Known good: the exact-kinematics reduced model (two modes per flexible link) is
    ν-close to the linearised FE arm in what the three encoders see: measured 0.036 at
    rest and 0.050 at θ = (0, 1, 0.5) rad, peaking at 28 Hz (the FE's third bending mode,
    which two assumed modes place higher).  The bound 0.1 is twice the worse of them and
    far below the known-bad gap next."""
    assert _three_link_theta_gap(1.0, theta) < bound


def test_a_three_link_model_with_twice_the_stiffness_is_far_from_its_fe_arm():
    """Known bad: EI × 2 on both flexible links moves every lightly damped resonance by
    √2, far beyond its bandwidth: δν = 0.878 at rest (peak at 10 Hz), against 0.036."""
    assert _three_link_theta_gap(2.0) > 0.5


def test_the_validity_map_of_the_three_link_arm(monkeypatch):
    """`arm_validity` on three joints: the τ → θ view is 3×3 and close (0.036 at rest),
    the frequency responses have one τ_i → θ_i per joint and a tip channel per flexible
    link (link 1 is rigid), and the loop of the scenario's law is computed (0.67)."""
    from validation.run.scenario import scenario_from_mapping, scenario_to_mapping
    from validation.verdicts import validity
    monkeypatch.setattr(validity, "THETA2", (0.0,))
    config = scenario_to_mapping(scenario_from_mapping({
        "arm": "three-link", "observer": {"kind": "none"}, "model": {"kinematics": "exact"}}))
    data = validity.arm_validity(config)
    (gap,) = data["gaps"]
    assert gap["theta"] < 0.1 and 0 < gap["loop"] <= 1
    assert list(data["responses"][0]["fe"]) == [
        "tau1->theta1", "tau2->theta2", "tau3->theta3", "tau2->tip_defl2", "tau3->tip_defl3"]
