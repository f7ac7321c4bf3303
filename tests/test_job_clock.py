"""The paper reproduction's one estimate of the time left (issue 46, 1): the reference
times of the phases to come, scaled by this machine's pace on the phases that ran."""
import io

import pytest

from validation.cli.job_clock import LAB, PAPER, RESUMED, JobClock

PHASES = (("a", 100.0), ("b", 200.0), ("c", 50.0))


class Clock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def lines(phases, steps, skipped=()):
    out, clock = io.StringIO(), Clock()
    job = JobClock("job", phases, stream=out, clock=clock)
    job.begin(skipped=skipped)
    for phase, seconds in steps:
        clock.now += seconds
        job.done(phase)
    return out.getvalue().splitlines()


def test_the_total_and_the_time_left_follow_this_machines_pace():
    """A machine twice as slow as the reference: phase a takes 200 s, so b and c
    (250 s on the reference) are about 500 s = 8 min away."""
    said = lines(PHASES, [("a", 200.0), ("b", 400.0), ("c", 100.0)])
    assert said[0].startswith("job: 3 phases (a, b, c), about 6 min")  # 350 s reference
    assert said[1] == "job: a took 3 min; about 8 min left (b, c)"
    assert said[2] == "job: b took 7 min; about 2 min left (c)"  # 100 s
    assert len(said) == 3  # nothing after the last phase


def test_a_resumed_phase_says_nothing_of_the_pace():
    """Known-bad without the rule: phase a read its stored runs in 1 s (1 % of its
    reference), which would have made b and c look 100x faster (2.5 s left)."""
    said = lines(PHASES, [("a", 1.0)])
    assert 1.0 < RESUMED * 100.0
    assert said[1] == "job: a took 1 s; about 4 min left (b, c)"  # the reference: 250 s


def test_skipped_phases_are_left_out_and_the_paper_has_its_phases():
    said = lines(PHASES, [], skipped=["b"])
    assert said[0].startswith("job: 2 phases (a, c), about 2 min")  # 150 s
    assert [p for p, _ in PAPER][:2] == ["the paper's runs", "the stability map"]
    assert all(seconds > 0 for _, seconds in PAPER)


def test_the_lab_job_names_the_paper_jobs_phases_but_its_runs():
    """``reproduce-paper --lab`` says its plan and time left through the same clock and
    the same calls as the paper's job: its profile names every phase the command ends
    (and skips) but the first, its runs.  Known-bad: a profile without a phase the
    command ends fails at that phase's end."""
    assert [p for p, _ in LAB][1:] == [p for p, _ in PAPER][1:]
    assert LAB[0][0] != PAPER[0][0] and all(seconds > 0 for _, seconds in LAB)
    said = lines(LAB, [(LAB[0][0], 60.0)], skipped=["the stability map"])
    assert said[0].startswith(f"job: {len(LAB) - 1} phases ({LAB[0][0]}, the mesh checks")
    with pytest.raises(KeyError):
        lines(LAB[1:], [(PAPER[0][0], 60.0)])
