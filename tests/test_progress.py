"""Progress that tells the truth: the kernel compile reports each group with an estimate
of the rest, the stability map names its round, and failed runs make the command exit 1."""
import io


from validation.batch.compiling import compile_groups
from validation.cli import main


def test_compile_reports_each_group_with_the_time_left():
    """Groups that load from the cache are silent; each group that compiles is reported
    with the time left: the remaining groups' reference times scaled by this machine's
    pace.  Here every compile takes 2 s: after "model" (reference 1 s: twice as slow)
    2 × (5 + 3 + 6) = 28 s at most are left (the cached group is counted until it loads);
    after "pbc" (4 s for 4 s of reference) 1 × 6 = 6 s."""
    durations = iter([2.0, 0.125, 2.0, 2.0])  # "cached" loads in 0.125 s (exact in binary)
    now = [0.0]

    def clock():
        return now[0]
    done = []

    def build(name):
        def run():
            done.append(name)
            now[0] += next(durations)
        return run
    groups = [(name, build(name)) for name in ("model", "cached", "pbc", "smo")]
    reference = {"model": 1.0, "cached": 5.0, "pbc": 3.0, "smo": 6.0}
    stream = io.StringIO()
    taken = compile_groups(groups, stream=stream, clock=clock, reference=reference)
    lines = stream.getvalue().splitlines()
    assert done == ["model", "cached", "pbc", "smo"]
    assert taken == {"model": 2.0, "cached": 0.125, "pbc": 2.0, "smo": 2.0}
    assert "once per checkout" in lines[0] and "4 groups, about 15 s" in lines[0]
    assert lines[1:] == ["  [1/4] model: 2 s; at most about 28 s left",
                         "  [3/4] pbc: 2 s; at most about 6 s left",
                         "  [4/4] smo: 2 s"]
    quiet = io.StringIO()
    compile_groups([("x", lambda: None)], stream=quiet)  # nothing compiles: nothing said
    assert quiet.getvalue() == ""


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
