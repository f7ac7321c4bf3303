"""Progress that tells the truth: the kernel compile reports each group with an estimate
of the rest, the stability map names its round, and a limit a failed run leaves missing
makes the command exit 1;
a bar on a terminal, a few plain lines in a log."""
import io

from validation.batch.compiling import compile_groups
from validation.batch.progress import LineProgress, progress
from validation.cli import main


def test_compile_reports_each_group_with_the_time_left():
    """Groups that load from the cache are silent; each group that compiles is reported
    with the groups ready (a count that only grows; those loaded from the cache since the
    last line said) and the time left: the remaining groups' reference times scaled by
    this machine's pace.  Here every compile takes 2 s: after "model" (reference 1 s: twice
    as slow) 2 × (5 + 3 + 6) = 28 s are left (the cached group is counted until it loads);
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
    assert lines[1:] == ["  model: 2 s — 1 of 4 groups ready, about 28 s left",
                         "  pbc: 2 s — 3 of 4 groups ready (1 loaded from the cache), "
                         "about 6 s left",
                         "  smo: 2 s — 4 of 4 groups ready"]
    quiet = io.StringIO()
    compile_groups([("x", lambda: None)], stream=quiet)  # nothing compiles: nothing said
    assert quiet.getvalue() == ""


FAILING_LAW = '''
class Boom:
    """A controller whose every call fails (a solver failure stands in for any)."""

    def __init__(self, model, *, Ts):
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
    assert "limit(s) missing: a run failed where the limit is" in capsys.readouterr().out


def test_the_stability_map_names_its_round(tmp_path, capsys):
    # The LQR has no finite predicted limit: its map starts from the grid, and bisects
    # the tracking limit Table 1's arm loses at 4.4 ms.
    (tmp_path / "s.toml").write_text('[controller]\nkind = "lqr"\n[observer]\nkind = "none"\n')
    assert main(["stability", str(tmp_path / "s.toml"), "--plant", "reduced", "--arm",
                 "table1", "--workers", "1", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "stability: start" in err and "stability: bisection 1 (to 0.01)" in err


def test_the_compile_never_repeats_an_estimate():
    """Two groups after which the same time is left (the second took exactly its
    reference time after the first did too): the estimate is said once."""
    now = [0.0]

    def build(seconds):
        def run():
            now[0] += seconds
        return run
    stream = io.StringIO()
    compile_groups([("a", build(2.0)), ("b", build(0.0 + 2.0)), ("c", build(60.0)),
                    ("d", build(2.0))], stream=stream, clock=lambda: now[0],
                   reference={"a": 2.0, "b": 2.0, "c": 60.0, "d": 2.0})
    lines = stream.getvalue().splitlines()[1:]
    assert lines[0] == "  a: 2 s — 1 of 4 groups ready, about 64 s left"
    assert lines[1] == "  b: 2 s — 2 of 4 groups ready, about 62 s left"
    assert sum("left" in line for line in lines) == len({line.rpartition(", ")[2]
                                                         for line in lines if "left" in line})


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_progress_in_a_log_is_a_few_plain_lines():
    """Not a terminal (a file, a pipe): no carriage return, a line at the start, at each
    tenth crossed (no more than one per 30 s) and at the end — 300 runs over 20 min make
    12 lines, not a redraw per run."""
    clock, stream = Clock(), io.StringIO()
    bar = LineProgress(300, "paper", stream=stream, clock=clock)
    for i in range(300):
        clock.now += 4.0
        bar.set_postfix(ok=i + 1, failed=0)
        bar.update(1)
    bar.close()
    bar.close()  # closing twice says nothing more
    text = stream.getvalue()
    lines = text.splitlines()
    assert "\r" not in text
    assert lines[0] == "paper: 300 runs to do"
    assert lines[1] == "paper: 30/300 runs (10 %), 2 min 00 s, about 18 min 00 s left; ok 30, failed 0"
    assert lines[-1] == "paper: 300/300 runs (100 %), 20 min 00 s; ok 300, failed 0"
    assert len(lines) == 11  # start, 10 %..90 %, end


def test_progress_lines_are_at_least_30_s_apart():
    """A fast job (60 runs in 6 s) says when it starts and when it ends."""
    clock, stream = Clock(), io.StringIO()
    bar = LineProgress(60, "sweep", stream=stream, clock=clock)
    for _ in range(60):
        clock.now += 0.1
        bar.update(1)
    bar.close()
    assert stream.getvalue().splitlines() == ["sweep: 60 runs to do",
                                             "sweep: 60/60 runs (100 %), 6 s"]


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_terminal_gets_a_bar_a_file_gets_lines_and_disabled_is_silent():
    assert isinstance(progress(3, "x", stream=io.StringIO()), LineProgress)
    tty = Terminal()
    bar = progress(3, "x", stream=tty)
    bar.update(3)
    bar.close()
    assert "\r" in tty.getvalue() and "3/3" in tty.getvalue()  # tqdm, redrawn in place
    quiet = io.StringIO()
    silent = progress(3, "x", stream=quiet, enabled=False)
    silent.update(3)
    silent.close()
    assert quiet.getvalue() == ""


def test_a_campaign_logged_to_a_file_has_no_carriage_return(tmp_path, capfd):
    """`flexarm campaign` with stderr not a terminal (here: captured): plain lines."""
    (tmp_path / "c.toml").write_text(
        'name = "c"\n[scenario]\nduration = 0.05\n[scenario.controller]\nkind = "pd"\n'
        '[scenario.observer]\nkind = "none"\n[[sweep]]\ngrid.seed = [1, 2, 3]\n')
    assert main(["campaign", str(tmp_path / "c.toml"), "--workers", "1",
                 "--out", str(tmp_path / "o")]) == 0
    err = capfd.readouterr().err
    assert "\r" not in err
    assert "c: 3 runs to do" in err and "c: 3/3 runs (100 %)" in err
