"""The ``flexarm`` command line: output and one-line errors with exit status 2."""

import pytest

from cli_testing import flexarm, program
from validation.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("flexarm-validation ")


def test_modes_prints_table1_frequencies(capsys):
    assert main(["modes", "--arm", "table1", "--theta2", "0", "1.5708"]) == 0
    out = capsys.readouterr().out
    assert "0.6316" in out and "3.8313" in out and "2.2359" in out  # locked / free at θ2 = 0
    assert out.count("joints locked") == 2 and "Table 1" in out


def test_modes_reads_params_toml(tmp_path, capsys):
    path = tmp_path / "arm.toml"
    path.write_text("[params]\nMp = 0.5\n")
    assert main(["modes", "--params", str(path)]) == 0
    assert str(path) in capsys.readouterr().out


def test_arms_lists_the_shipped_arms_and_shows_one(capsys):
    """``flexarm arms``: every shipped arm with its links and plane; one arm in full, its
    clamped-mass frequencies those of `flexarm modes`."""
    from reduced_model import named_arms
    assert main(["arms"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in named_arms()) and "R+F+F" in out and "vertical" in out
    assert main(["arms", "three-link"]) == 0
    out = capsys.readouterr().out
    assert "link 1: 0.3 m, 1.5 kg/m, rigid" in out and out.count("clamped-mass modes") == 2
    assert "EI3" in out and "EI4" not in out


def test_modes_on_a_single_link_and_a_three_link_arm(capsys):
    assert main(["modes", "--arm", "single-link"]) == 0
    out = capsys.readouterr().out
    assert "Reduced model, 2 clamped-mass modes" in out and "theta2" not in out
    assert main(["modes", "--arm", "three-link", "--modes-per-link", "0", "3", "1"]) == 0
    out = capsys.readouterr().out
    assert "0+3+1 clamped-mass modes" in out and "rigid" in out


def test_modes_compare_prints_fe_next_to_reduced(capsys):
    assert main(["modes", "--arm", "table1", "--compare", "--theta2", "0"]) == 0
    out = capsys.readouterr().out
    assert out.count("FE  ") == 2 and out.count("gap [%]") == 2
    assert "31.4327" in out  # FE free 3rd mode (the reduced model's truncation gap)


@pytest.mark.parametrize("args, text", [
    (["modes", "--compare", "--elements", "0"], "--elements: must be in 1..64"),
    (["modes", "--table1"], "--table1: is now --arm table1"),
    (["modes", "--arm", "single-link", "--theta2", "1"], "--theta2: needs a joint 2"),
    (["arms", "nope"], "arm: 'nope' is not a shipped arm"),
    (["modes", "--modes-per-link", "5", "2"], "--modes-per-link must be one integer in 0..4 per link"),
    (["modes", "--params", "/nonexistent/arm.toml"], "cannot read"),
    (["modes", "--params", "{bad_field}"], "params.Lx is not a field of this 2-link arm"),
    (["modes", "--params", "{negative}"], "params.EI1 must be >= 0, got -3.0"),
    (["modes", "--params", "{not_toml}"], "invalid TOML"),
    (["nonsense"], "invalid choice"),
])
def test_bad_input_one_line_exit_2(tmp_path, args, text):
    files = {"bad_field": "Lx = 1.0\n", "negative": "EI1 = -3.0\n", "not_toml": "EI1 = = 3\n"}
    for key, content in files.items():
        (tmp_path / f"{key}.toml").write_text(content)
    args = [a.format(**{k: str(tmp_path / f"{k}.toml") for k in files}) for a in args]
    proc = program(None, *args)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error:"), proc.stderr
    assert text in lines[0]


def test_modes_table1_prints_the_independent_reference_without_negative_zero(capsys):
    assert main(["modes", "--arm", "table1"]) == 0
    out = capsys.readouterr().out
    # The independent references (a converged Euler–Bernoulli FE model built outside this code), next to ours.
    assert "0.6316     3.8312     6.3499    33.6650" in out
    assert "2.2359     6.1233    31.4140    34.3020" in out
    assert out.count("gap to reference [%]") == 2 and "-0.0000" not in out
    assert "the paper publishes no frequencies" in out


# --- a first hour: single runs that say what they are and reproduce what is stored --------
NOISY = {"duration": 0.6, "transient": 0.2, "sensors": {"encoder_noise": 1e-4,
         "modal_noise": 1e-5, "rate_noise": 1e-3},
         "observer": {"kind": "smo-bl", "initial_error": [0.1, 5e-3, 0.3, 0.05]}}


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A results folder with two runs of one name (two seeds) from a campaign."""
    from validation.batch.campaign import campaign_from_mapping
    from validation.batch.queue import run_campaign
    out = tmp_path_factory.mktemp("stored")
    run_campaign(campaign_from_mapping({"name": "c", "scenario": NOISY, "sweep": [
        {"name": "noisy", "grid": {"seed": [1, 2]}}]}), out, progress=False)
    return out


def test_a_short_run_states_its_window(tmp_path, capsys):
    """The default transient fits a 1 s run (half of it) and the output says so."""
    from validation.batch.store.folder import ResultStore
    assert main(["run", "--duration", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "metrics after the 0.5 s transient, over 0.5–1 s" in out
    (row,) = ResultStore(tmp_path).rows()
    assert row.metrics["transient_s"] == 0.5 and row.config["transient"] == 0.5
    assert row.name == "pbc@reduced"  # named from what it is, not "paper"


def test_run_help_shows_every_default(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    for text in ("(default: 20)", "(default: 0.001)", "(default: none)", "(default: pbc)",
                 "noise: none", "transient 2 s, or half of a run shorter than 4 s",
                 "campaigns/base.toml", "--like"):
        assert text in out, text


def test_rerun_like_a_stored_run_reproduces_its_metrics(stored, tmp_path, capsys):
    """--like reruns the stored scenario exactly (noise, seed, initial error included)
    and gives the stored metrics to 1e-12 (the same code, the same arithmetic: any
    difference is a scenario that was not reproduced)."""
    from validation.batch.store.folder import ResultStore
    row = ResultStore(stored).rows()[0]
    assert main(["run", "--like", f"{stored}/{row.run_id}", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"rerunning {row.run_id} (c/noisy, stored in {stored}) exactly" in out
    assert "the stored metrics are reproduced" in out
    (again,) = ResultStore(tmp_path).rows()
    assert again.run_id == row.run_id and again.name == row.name
    for key, value in row.metrics.items():
        if key in ("wall_s", "startup_s", "realtime_factor") or key in row.timings:
            continue
        if isinstance(value, float):
            assert again.metrics[key] == pytest.approx(value, rel=1e-12, abs=1e-300, nan_ok=True), key
        else:
            assert again.metrics[key] == value, key


def test_rerun_like_with_changes_says_which(stored, tmp_path, capsys):
    from validation.batch.store.folder import ResultStore
    row = ResultStore(stored).rows()[0]
    assert main(["run", "--like", f"{stored}/{row.run_id[:6]}", "--set", "seed=7",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "with 1 change(s): seed = 7 (was " in out and "reproduced" not in out


def test_rerun_like_an_ambiguous_name_lists_the_ids(stored, capsys):
    assert main(["run", "--like", f"{stored}/noisy"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 runs of" in err and "give one's id" in err


def test_a_truth_plant_run_says_whether_it_converged(tmp_path, capsys):
    """A plain truth-plant run says that its convergence was not checked; --mesh-check
    runs its checks (level 1 and GE decide here: level 2 is said to be not needed, issue
    46) and says whether its judged values agree; --like by its name then means the
    nominal run, not one of the checks that share the name."""
    from validation.batch.store.folder import ResultStore
    short = ["--plant", "exudyn", "--duration", "0.05", "--observer", "none"]
    assert main(["run", *short, "--out", str(tmp_path / "plain")]) == 0
    assert "convergence not checked: these are the FE model's numbers on ANCF 4 el/link" \
        in capsys.readouterr().out
    out = tmp_path / "checked"
    assert main(["run", *short, "--mesh-check", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "converged against ANCF 8 el/link, step/2; GE 32 el/link, step/2 (ANCF 16 " \
           "el/link, step/4: not needed, the first level decides)" in printed
    rows = ResultStore(out).rows()
    (nominal,) = [r for r in rows if r.sweep != "mesh-check"]
    assert len(rows) == 3 and {r.name for r in rows} == {"pbc@exudyn"}
    assert main(["run", "--like", f"{out}/pbc@exudyn", "--out", str(tmp_path / "again")]) == 0
    printed = capsys.readouterr().out
    assert f"rerunning {nominal.run_id} (pbc@exudyn, stored in {out}; the nominal run: its 2 " \
           "mesh/step check(s) share its name" in printed
    assert main(["run", *short[2:], "--mesh-check"]) == 2  # the reduced plant has no mesh
    assert "--mesh-check: the reduced plant is not a discretisation" in capsys.readouterr().err


def test_a_failed_run_names_no_window_and_no_figures(tmp_path, capsys, plugin_lab):
    """A plug-in returning torques of the wrong shape fails at t = 0: no "window over
    0.5–0 s", no negative real-time factor, no `flexarm show` hint (it draws ok runs)."""
    plugin_lab({"wronglab.py": "import numpy as np\n\nclass Wrong:\n    def __init__(self, m, *, Ts):"
                               "\n        pass\n\n    def __call__(self, t, x, ref):\n"
                               "        return np.zeros(3)\n"})
    assert main(["run", "--controller", "wronglab:Wrong", "--duration", "1",
                 "--out", str(tmp_path)]) == 1
    printed = capsys.readouterr()
    out = printed.out + printed.err
    assert "no metrics: the run failed after 0 of 1 s" in printed.err
    assert "0.5–0 s" not in out and "real-time factor" not in out and "flexarm show" not in out


RAISING = """import numpy as np


class JointPD:
    name = "mypd"

    def __init__(self, model, *, Ts):
        pass

    def __call__(self, t, x, ref):
        raise RuntimeError("gain table missing")
"""


def test_a_failing_plugin_is_named_as_written_and_said_on_stderr(tmp_path, capsys,
                                                                   plugin_lab):
    """Issue 58: the failure went to stdout only (stderr empty), the run was labelled
    "JointPD@exudyn" while the error said "mypd", and a failed truth-plant run was still
    advised to check its convergence (--mesh-check)."""
    from validation.batch.store.folder import ResultStore
    plugin_lab({"mypdlab.py": RAISING})
    assert main(["run", "--controller", "mypdlab:JointPD", "--plant", "exudyn",
                 "--duration", "0.05", "--out", str(tmp_path)]) == 1
    printed = capsys.readouterr()
    assert "failed: mypd raised RuntimeError: gain table missing at t = 0 s" in printed.err
    assert "mypdlab.py:11 in __call__" in printed.err and "failed" not in printed.out
    assert printed.out.startswith("mypd@exudyn: mypdlab:JointPD on the exudyn plant")
    assert "convergence" not in printed.out + printed.err
    (row,) = ResultStore(tmp_path).rows()
    assert row.name == "mypd@exudyn"


def test_run_config_takes_a_campaigns_scenario_base(tmp_path, capsys):
    from validation.batch.store.folder import ResultStore
    camp = tmp_path / "camp.toml"
    camp.write_text('name = "x"\n[scenario]\nduration = 0.4\n[scenario.sensors]\n'
                    'encoder_noise = 1e-4\n[[sweep]]\nname = "s"\ngrid.seed = [1, 2]\n')
    assert main(["run", "--config", str(camp), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "is a campaign: running its [scenario] base (its 1 sweep(s) are not run" in out
    (row,) = ResultStore(tmp_path / "o").rows()
    assert row.config["sensors"]["encoder_noise"] == 1e-4 and row.config["duration"] == 0.4


def test_show_draws_the_paper_figures_of_one_run(stored, capsys):
    from validation.batch.store.folder import ResultStore
    row = ResultStore(stored).rows()[0]
    assert main(["show", f"{stored}/{row.run_id}", "--no-open"]) == 0
    folder = stored / "show" / row.run_id
    names = sorted(p.name for p in folder.glob("*.png"))
    assert names == ["fig3_tracking.png", "fig4_deflections.png", "fig5-6_rates.png",
                     "fig7_estimation_errors.png", "fig8_phase_portrait.png"]
    assert all((folder / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in names)
    assert str(folder / "index.html") in capsys.readouterr().out


def test_show_overlays_the_same_scenario_on_the_other_plant_whatever_the_names(tmp_path, capsys):
    """`flexarm run` names runs by their plant ("pd@reduced", "pd@exudyn"): `show` of
    either draws the other over it, as the same scenario but the plant."""
    from validation.batch.store.folder import ResultStore
    out = tmp_path / "o"
    for plant in ("reduced", "exudyn"):
        assert main(["run", "--plant", plant, "--controller", "pd", "--observer", "none",
                     "--duration", "0.1", "--out", str(out)]) == 0
    rows = {r.plant: r for r in ResultStore(out).rows()}
    assert {r.name for r in rows.values()} == {"pd@reduced", "pd@exudyn"}
    capsys.readouterr()
    assert main(["show", f"{out}/pd@reduced", "--no-open"]) == 0
    printed = capsys.readouterr().out
    assert f"with {rows['exudyn'].run_id}, the same scenario on the exudyn plant, overlaid" \
        in printed


def test_a_missing_results_folder_is_not_sent_to_repair(tmp_path, capsys):
    """Issue 47: `flexarm report results/nosuch` suggested `flexarm repair`, which then
    failed.  The cure is named only where it has run files to read."""
    assert main(["report", str(tmp_path / "nosuch")]) == 2
    err = capsys.readouterr().err
    assert "not a results folder (no such folder)" in err and "repair" not in err
    (tmp_path / "bare").mkdir()
    assert main(["report", str(tmp_path / "bare")]) == 2
    assert "(no index.sqlite, no runs/)" in capsys.readouterr().err
    (tmp_path / "bare" / "runs").mkdir()
    assert main(["report", str(tmp_path / "bare")]) == 2
    assert f"'flexarm repair {tmp_path / 'bare'}' rebuilds it" in capsys.readouterr().err
    assert main(["repair", str(tmp_path / "bare")]) == 0  # the cure named works


WARNING_LAW = '''
import warnings

import numpy as np


class Law:
    def __init__(self, model, *, Ts):
        pass

    def __call__(self, t, x, ref):
        warnings.warn("a plug-in's warning", RuntimeWarning)
        return np.zeros(2)
'''


@pytest.mark.parametrize("args, status", [
    (["run", "--controller", "warnlaw:Law", "--duration", "0.01", "--out", "o"], 0),
    (["run", "--set", "true_params.EI1=-1.0", "--out", "bad"], 2),
])
def test_a_forked_command_prints_what_the_program_prints(tmp_path, args, status):
    """The tests' `cli_testing.flexarm` (a child forked from the test process) gives the
    program's exit status and stderr, warnings included.  Known bad: a child that kept the
    test process's warning capture (pytest's) would print no warning, and the tests that
    check a command prints none could not fail."""
    (tmp_path / "warnlaw.py").write_text(WARNING_LAW)
    forked, started = flexarm(tmp_path, *args), program(tmp_path, *args)
    assert forked.returncode == started.returncode == status, (forked.stderr, started.stderr)
    assert forked.stderr == started.stderr != ""
    assert ("RuntimeWarning: a plug-in's warning" in forked.stderr) == (status == 0)
