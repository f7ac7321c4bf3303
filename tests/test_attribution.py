"""Shapley attribution: efficiency, null player, order independence, diverged worlds,
and the command line (each property would fail on a wrong implementation)."""
import itertools
import math

import pytest

from cli_testing import flexarm
from validation.report.verdict_tables import write_attribution
from validation.verdicts import attribution as att
from validation.run.config import ConfigError
from validation.run.scenario import scenario_from_mapping

PLAYERS = ("plant", "parameters", "sensing", "sampling")


def world_metrics(track_max: float) -> dict:
    """A run's metrics where every attributed metric is a function of one number."""
    return {"track_max_1": track_max, "track_max_2": 0.0, "track_rms_1": track_max,
            "track_rms_2": track_max, "vib_rms_1": 2 * track_max, "vib_rms_2": 0.0,
            "tau_tv_1": track_max, "tau_tv_2": 1.0}


def game(value, players=PLAYERS, truncated=None):
    """metrics_of for every world of ``players``: m(S) = value(S)."""
    out = {}
    for mask in itertools.product((True, False), repeat=len(players)):
        real = frozenset(p for p, r in zip(players, mask) if r)
        level = "real" if "plant" in real else "ideal"
        out[(real, level)] = None if value(real) is None else world_metrics(value(real))
        if truncated and "plant" not in real:
            out[(real, "truncated")] = world_metrics(truncated(real))
    return out


# Additive part a_f, plus an interaction of plant and sampling of size b.
A = {"plant": 0.010, "parameters": 0.004, "sensing": 0.0, "sampling": 0.002}
B = 0.006


def additive(S):
    return 0.001 + sum(A[f] for f in S) + (B if {"plant", "sampling"} <= S else 0.0)


def test_efficiency_null_player_and_the_closed_form():
    a = att.compute("x", PLAYERS, game(additive))
    phi = a.contributions["track_max"]
    # Shapley of an additive game plus a pairwise term: a_f, and b/2 to each of the pair.
    assert phi["plant"] == pytest.approx(A["plant"] + B / 2, abs=1e-15)
    assert phi["sampling"] == pytest.approx(A["sampling"] + B / 2, abs=1e-15)
    assert phi["parameters"] == pytest.approx(A["parameters"], abs=1e-15)
    assert phi["sensing"] == 0.0  # a null player gets exactly zero, not ~1e-17
    total = a.totals["track_max"]
    assert total == pytest.approx(sum(A.values()) + B, abs=1e-15)
    assert sum(phi.values()) == pytest.approx(total, abs=1e-15)  # efficiency
    assert a.interaction["track_max"][0] == ("plant", "sampling")
    assert a.interaction["track_max"][1] == pytest.approx(B, abs=1e-15)


def test_the_result_does_not_depend_on_the_order_of_the_factors():
    first = att.compute("x", PLAYERS, game(additive))
    again = att.compute("x", tuple(reversed(PLAYERS)), game(additive, tuple(reversed(PLAYERS))))
    assert first.contributions == again.contributions  # bit-identical, not just close
    # The sequential ladder does depend on it (that is why it is only shown for contrast).
    assert first.ladder["track_max"] != again.ladder["track_max"]


def test_the_plant_is_split_along_the_truncation_sub_ladder():
    # The 4+4 reduced plant sits 30 % of the way from the controller's model to the FE.
    truncated = lambda S: additive(S) + 0.3 * A["plant"] + (0.3 * B if "sampling" in S else 0)  # noqa: E731
    a = att.compute("x", ("plant", "truncation") + PLAYERS[1:], game(additive, truncated=truncated))
    phi = a.contributions["track_max"]
    left_out, beyond = phi["plant: modes left out"], phi["plant: beyond assumed modes"]
    assert left_out + beyond == pytest.approx(phi["plant"], abs=1e-15)
    assert left_out == pytest.approx(0.3 * (A["plant"] + B / 2), abs=1e-15)


def test_diverged_worlds_are_held_out_by_the_stated_rule():
    # Every world with both plant and sampling real diverges: the smallest set meeting
    # all of them is one factor; the first in order ("plant") is held at its ideal level.
    value = lambda S: None if {"plant", "sampling"} <= S else additive(S)  # noqa: E731
    a = att.compute("x", PLAYERS, game(value))
    assert a.destabilising == ["plant"]
    assert "parameters+plant+sampling+sensing" in a.diverging
    assert math.isnan(a.real_value["track_max"])  # the real world has no number
    phi = a.contributions["track_max"]
    assert math.isnan(phi["plant"])
    # Over the others (plant held ideal) the game is additive again: a_f exactly, and
    # efficiency holds for m(real with plant ideal) − m(ideal).
    assert phi["sampling"] == pytest.approx(A["sampling"], abs=1e-15)
    assert phi["parameters"] + phi["sensing"] + phi["sampling"] == pytest.approx(
        a.totals["track_max"], abs=1e-15)


def test_a_real_attribution_on_the_reduced_plant(tmp_path):
    """Four factors, 16 short runs: the contributions add up to the gap of the stored
    runs, and 'actuation' (a torque limit never reached) is exactly null."""
    s = scenario_from_mapping({
        "duration": 2.5, "initial_state": "reference", "torque_limit": 50.0,
        "true_params": {"Mp": 0.3}, "observer": {"kind": "smo-bl"},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}})
    factors = ("parameters", "sensing", "estimation", "actuation")
    a, summary = att.attribute(s, factors, tmp_path, name="t", progress=False)
    assert summary.ok == 16
    for metric, phi in a.contributions.items():
        assert sum(phi.values()) == pytest.approx(a.totals[metric], rel=1e-12, abs=1e-15)
        assert a.totals[metric] == pytest.approx(a.real_value[metric] - a.ideal_value[metric],
                                                 rel=1e-12, abs=1e-15)
        assert phi["actuation"] == 0.0
    # The payload error dominates the tracking gap (measured ~100 %).
    assert a.contributions["track_max"]["parameters"] > 0.5 * a.totals["track_max"]
    text = write_attribution([a], tmp_path)
    assert "## t" in text and (tmp_path / "attribution.csv").read_text().count("\n") > 8


@pytest.mark.parametrize("args, text", [
    (["--factors", "plant,weather"], "unknown factor 'weather'"),
    (["--factors", ""], "needs at least one factor"),
    (["--factors", "estimation"], "'estimation' cannot be idealised"),
    (["--factors", "truncation"], "'truncation' splits the 'plant' factor"),
    (["--factors", "kinematics"], "does not have the exact kinematics"),
])
def test_bad_factors_are_one_line_errors_and_nothing_is_written(tmp_path, args, text):
    cfg = tmp_path / "s.toml"
    cfg.write_text("duration = 3.0\n")
    out = tmp_path / "out"
    proc = flexarm(None, "attribute", cfg, "--out", out, *args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and text in lines[0], proc.stderr
    assert not out.exists()


def test_the_joints_are_factors_of_their_own(tmp_path):
    """The lab arm's joints as factors on the reduced plant (2.5 s, 16 worlds): each world
    switches the true and the nominal arm alike, the contributions add up to the gap,
    'bandwidth' on an arm without current loops is exactly null, and 'parameters' leaves
    the joint factors' fields alone (with friction ideal, the world with parameters ideal
    has no friction, whatever the nominal arm says)."""
    s = scenario_from_mapping({
        "duration": 2.5, "initial_state": "reference", "arm": "lab",
        "true_params": {"Mp": 0.3, "torque_time_constant1": 0.0,
                        "torque_time_constant2": 0.0},
        "nominal_params": {"coulomb1": 0.0}})
    factors = ("friction", "drive", "bandwidth", "parameters")
    worlds = att.plan(s, factors, "j")
    by_real = {w.real: w.run.scenario for w in worlds}
    ideal = by_real[frozenset()]
    assert (ideal.true_params.joints[0].static_friction
            == ideal.nominal_params.joints[0].static_friction == 0)
    assert not ideal.true_params.joints[0].has_drive and ideal.true_params.Mp == 0.1
    only_friction = by_real[frozenset({"friction"})].true_params
    assert only_friction.coulomb1 == 0.3 and only_friction.Mp == 0.1  # the arm's, not nominal's
    a, summary = att.attribute(s, factors, tmp_path, name="j", progress=False)
    assert summary.ok == 16
    for metric, phi in a.contributions.items():
        assert sum(phi.values()) == pytest.approx(a.totals[metric], rel=1e-12, abs=1e-15)
        assert phi["bandwidth"] == 0.0
        assert phi["friction"] != 0.0


def test_gravity_is_a_factor_of_the_vertical_arm(tmp_path):
    """The vertical two-link arm on the reduced plant (2.5 s, 16 worlds): 'gravity' is
    among the default factors, and with it the contributions add up to the gap of the
    stored runs — exactly, up to the rounding of a sum of 16 terms (rel 1e-12) — and
    gravity costs something (an arm in gravity sags under its own weight)."""
    s = scenario_from_mapping({
        "duration": 2.5, "initial_state": "reference", "arm": "vertical-two-link",
        "true_params": {"Mp": 0.2}, "observer": {"kind": "smo-bl"},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}})
    assert "gravity" in att.default_factors(s)
    factors = ("gravity", "parameters", "sensing", "estimation")
    a, summary = att.attribute(s, factors, tmp_path, name="v", progress=False)
    assert summary.ok == 16 and not a.destabilising
    for metric, phi in a.contributions.items():
        assert set(phi) == set(factors)
        assert sum(phi.values()) == pytest.approx(a.totals[metric], rel=1e-12, abs=1e-15)
    assert a.contributions["vib_rms"]["gravity"] != 0.0


def test_the_horizontal_paper_arm_has_no_gravity_factor(tmp_path):
    """Known bad: the paper's arm is horizontal — no default 'gravity' factor, and asking
    for one is a one-line error (a factor that cannot act would be a null player)."""
    s = scenario_from_mapping({})
    assert "gravity" not in att.default_factors(s)
    with pytest.raises(ConfigError, match="'gravity' cannot be idealised: the arm is horizontal"):
        att.parse_factors(["gravity", "sensing"], s)
