"""Progress that tells the truth: the kernel compile reports each group with an estimate
of the rest, the stability map names its round, and failed runs make the command exit 1."""
import io
import itertools

import pytest

from validation.batch.compiling import KernelGroup, compile_groups
from validation.cli import main


def test_compile_reports_each_group_with_the_time_left():
    """The estimate scales the reference times of the remaining groups by this machine's
    pace so far: after the first group (2 s for a 1 s reference: twice as slow) 2 × (3 + 6)
    = 18 s are left; after the second (4 s for 4 s of reference) 1 × 6 = 6 s."""
    ticks = itertools.count(step=2.0)  # every clock reading 2 s later: each group takes 2 s
    done = []
    groups = [KernelGroup(name, lambda name=name: done.append(name), expected)
              for name, expected in (("the model", 1.0), ("the PBC", 3.0), ("the SMO", 6.0))]
    stream = io.StringIO()
    taken = compile_groups(groups, stream=stream, clock=lambda: next(ticks))
    lines = stream.getvalue().splitlines()
    assert done == ["the model", "the PBC", "the SMO"] and taken == {n: 2.0 for n in done}
    assert "once per checkout" in lines[0] and "3 groups, about 10 s" in lines[0]
    assert lines[1] == "  [1/3] the model: 2 s; about 18 s left"
    assert lines[2] == "  [2/3] the PBC: 2 s; about 6 s left"
    assert lines[3] == "  [3/3] the SMO: 2 s; all compiled in 6 s"


FAILING_LAW = '''
class Boom:
    """A controller whose every call fails (a solver failure stands in for any)."""

    def __init__(self, model):
        pass

    def __call__(self, t, x, ref):
        raise RuntimeError("solver failed")
'''


def test_a_stability_map_with_failed_runs_exits_1(tmp_path, monkeypatch, capsys):
    (tmp_path / "failing_law.py").write_text(FAILING_LAW)
    (tmp_path / "s.toml").write_text('[controller]\nkind = "failing_law:Boom"\n')
    monkeypatch.chdir(tmp_path)  # plug-ins are found from the working directory
    status = main(["stability", "s.toml", "--plant", "reduced", "--arm", "default",
                   "--workers", "1", "--no-progress", "--out", str(tmp_path / "o")])
    assert status == 1
    assert "run(s) failed" in capsys.readouterr().err


def test_the_stability_map_names_its_round(tmp_path, capsys):
    (tmp_path / "s.toml").write_text('[controller]\nkind = "pd"\n')
    assert main(["stability", str(tmp_path / "s.toml"), "--plant", "reduced", "--arm",
                 "default", "--workers", "1", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "stability: grid" in err and "stability: bisection 1/3" in err
