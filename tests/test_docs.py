"""The documentation stays true (like python-control's doc/test_sphinxdocs.py): every
public name is in the API reference with numpydoc sections, the configuration and metric
references cover what the code defines, the examples in the pages run as written, the
commands they show exist, and the gallery's examples run (slow: ``make docs`` runs them
too).  Runs without the docs extra: the docstrings are read by the same small reader the
site's generators use."""
import dataclasses
import functools
import importlib
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
from cli_testing import flexarm  # noqa: E402
from flexarm_docs.docstrings import entries, sections  # noqa: E402

PACKAGES = ("validation", "reduced_model", "plant_exudyn", "controllers")

def public_names():
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            yield package, name, getattr(module, name)


def reference_names() -> dict[str, set[str]]:
    """The names each ``.. currentmodule::`` section of the API page lists."""
    out, current = {}, None
    for line in (DOCS / "reference" / "api.rst").read_text().splitlines():
        if m := re.match(r"\.\. currentmodule:: (\S+)", line):
            current = out.setdefault(m.group(1), set())
        elif current is not None and re.fullmatch(r"   [A-Za-z_]\w*", line):
            current.add(line.strip())
    return out


def test_every_public_name_is_in_the_api_reference():
    listed = reference_names()
    missing = [f"{p}.{n}" for p, n, _ in public_names() if n not in listed.get(p, set())]
    extra = [f"{p}.{n}" for p, names in listed.items() for n in names
             if n not in importlib.import_module(p).__all__]
    assert not missing, f"not in docs/reference/api.rst: {missing}"
    assert not extra, f"in docs/reference/api.rst but not public: {extra}"


def missing_sections(obj) -> list[str]:
    """What a public function's or class's docstring lacks: a Parameters entry per
    parameter of its signature, and Returns for a function."""
    if not (inspect.isfunction(obj) or inspect.isclass(obj)) or (
            inspect.isclass(obj) and (issubclass(obj, BaseException) and
                                      "__init__" not in vars(obj)
                                      or getattr(obj, "_is_protocol", False)
                                      or issubclass(obj, __import__("enum").Enum))):
        return []  # constants, protocols, enums and plain exceptions take no parameters
    params = [p.name for p in inspect.signature(obj).parameters.values()
              if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    documented = {e.name for e in entries(obj, "Parameters")}
    out = [f"parameter {p}" for p in params if p not in documented]
    if inspect.isfunction(obj) and not sections(obj).get("Returns"):
        out.append("Returns")
    return out


@pytest.mark.parametrize("package", PACKAGES)
def test_public_names_have_numpydoc_sections(package):
    """Every public name (issue 47: 26 were listed as exceptions, among them what a
    plug-in author needs most: resolve, CompiledLaw, compiled_form)."""
    lacking = {n: m for p, n, obj in public_names() if p == package
               for m in [missing_sections(obj)] if m}
    assert not lacking, f"{package}: docstrings lacking numpydoc sections: {lacking}"


def scenario_dataclasses():
    """Every dataclass a scenario file's keys reach (the configuration reference)."""
    import typing
    from validation import Scenario
    seen, todo = [], [Scenario]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.append(cls)
        for hint in typing.get_type_hints(cls).values():
            for tp in (hint, *typing.get_args(hint)):
                if dataclasses.is_dataclass(tp):
                    todo.append(tp)
    return seen


@pytest.mark.parametrize("cls", scenario_dataclasses(), ids=lambda c: c.__name__)
def test_every_configuration_key_is_documented(cls):
    documented = {e.name for e in entries(cls, "Parameters")}
    undocumented = [f.name for f in dataclasses.fields(cls) if f.name not in documented]
    assert not undocumented, f"{cls.__name__}: fields without a Parameters entry: {undocumented}"


def test_every_metric_key_is_documented_and_produced():
    from flexarm_docs.signalref import keys_by_pattern, sample_run
    _, metrics = sample_run()
    found = keys_by_pattern(metrics)
    matched = {k for keys in found.values() for k in keys}
    assert not set(metrics) - matched, f"undocumented metric keys: {set(metrics) - matched}"
    assert all(found.values()), f"documented, never produced: {[k for k, v in found.items() if not v]}"


def code_blocks(path: Path, language: str) -> list[str]:
    """The bodies of a page's ``.. code-block:: language`` directives, dedented."""
    out, lines = [], path.read_text().splitlines()
    for i, line in enumerate(lines):
        if line.strip() == f".. code-block:: {language}":
            body = []
            for follow in lines[i + 1:]:
                if follow.strip() and not follow.startswith("   "):
                    break
                body.append(follow[3:])
            out.append("\n".join(body).strip("\n") + "\n")
    return out


def test_bring_your_own_example_runs_as_written(tmp_path):
    page = DOCS / "guide" / "plugins.rst"
    files = {block.splitlines()[0].removeprefix("# "): block
             for lang in ("python", "toml") for block in code_blocks(page, lang)
             if re.fullmatch(r"# [\w./-]+\.(py|toml)", block.splitlines()[0])}
    assert {"mylab/control.py", "byo.toml"} <= set(files)
    for name in ("mylab/control.py", "byo.toml"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(files[name])
    commands = next(b for b in code_blocks(page, "sh") if "byo.toml" in b)
    for line in commands.strip().splitlines():
        args = line.split()
        if args[0] == "touch":
            (tmp_path / args[1]).touch()
            continue
        proc = flexarm(tmp_path, *args[1:])
        assert proc.returncode == 0, proc.stderr[-2000:]


def test_the_campaign_example_is_valid(tmp_path):
    """The complete campaign of the campaigns guide parses, checks and expands."""
    from validation import expand, load_campaign
    block = next(b for b in code_blocks(DOCS / "guide" / "campaigns.rst", "toml")
                 if b.startswith("# my.toml"))
    text = block.replace('include = "campaigns/base.toml"',
                         f'include = "{ROOT / "campaigns" / "base.toml"}"')
    (tmp_path / "my.toml").write_text(text)
    runs = expand(load_campaign(tmp_path / "my.toml"))
    assert len(runs) == 2 * 4 * 3 * 2 + 8
    assert {r.scenario.plant.kind for r in runs} == {"reduced", "exudyn"}
    assert runs[0].scenario.disturbances[0].kind == "pulse"


def shell_lines():
    pages = [*DOCS.glob("*.rst"), *DOCS.glob("guide/*.rst"), *DOCS.glob("theory/*.rst")]
    readme = re.findall(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    blocks = [b for p in pages for b in code_blocks(p, "sh")] + readme
    return [line for b in blocks for line in b.splitlines()
            if line.split("#")[0].split()[:1] == ["flexarm"]]


@pytest.mark.parametrize("line", shell_lines())
def test_commands_in_the_docs_name_real_flags(line):
    """Every ``flexarm COMMAND --flag`` the README and the pages show exists."""
    from validation.cli import build_parser
    words = line.split("#")[0].split()
    choices = build_parser()._subparsers._group_actions[0].choices
    if words[1].startswith("-"):
        return
    assert words[1] in choices, f"{line!r}: no command {words[1]}"
    sub = choices[words[1]]
    if words[1] == "baseline":
        sub = sub._subparsers._group_actions[0].choices[words[2].split("|")[0]]
    known = {o for a in sub._actions for o in a.option_strings}
    for w in words:
        flag = w.strip("[]").split("=")[0]
        if flag.startswith("--"):
            assert flag in known, f"{line!r}: {flag} is not a flag of {words[1]}"


def prose(rst: str) -> str:
    """A page's text as docutils would treat it as prose: without its code blocks (the
    indented bodies of ``::`` directives) and inline literals."""
    lines, keep = [], True
    for line in rst.splitlines():
        literal_block = line.startswith(".. code-block::") or (
            not line.startswith("..") and line.rstrip().endswith("::"))
        if literal_block:  # (a directive's "::", as list-table's, opens rst, not code)
            keep = False
            continue
        if not keep:
            if line.strip() and not line.startswith("   "):
                keep = True
            elif line.strip():
                continue
        lines.append(line)
    return re.sub(r"``.*?``", "", "\n".join(lines))


def test_the_cli_reference_has_no_flag_or_address_in_prose():
    """Issue 47: the built CLI page showed 16 flags as "–set" (docutils' smart quotes turn
    "--" into an en dash in prose: conf.py keeps quotes and ellipses only) and linked
    "controller+observer@plant" as mailto:.  Every flag and "@" word of the generated
    page is a literal (known-bad: the generator before wrapped none of them)."""
    from flexarm_docs import cliref
    text = prose(cliref.render(DOCS))
    assert not re.findall(r"(?<![\w-])--?[A-Za-z][\w-]*", text), \
        re.findall(r".{30}(?<![\w-])--?[A-Za-z][\w-]*.{10}", text)[:5]
    assert not re.findall(r"\w@\w", text)
    conf = (DOCS / "conf.py").read_text()
    assert 'smartquotes_action = "qe"' in conf and "mathjax_path = COMPONENT" in conf


#: A number as a page prints it: digits, a fraction, an exponent ("0.00963", "1e-05"); not
#: the digits inside a word ("smo2", "a3f9").
NUMBER = re.compile(r"(?<![\w.])(\d+)(?:\.(\d+))?(?:[eE][-+]?\d+)?(?![\w.]*\w)")
#: The significant digits a table may print: the report rounds to 3 (``fmt_number``), a
#: discretisation error to 2; 4 leaves room for a count ("1250 runs").
MAX_DIGITS = 4


def significant_digits(whole: str, fraction: str | None) -> int:
    """How many significant digits a printed number shows ("0.009627" → 4, "1000" → 1)."""
    digits = (whole + (fraction or "")).lstrip("0")
    return len(digits if fraction else digits.rstrip("0"))


def table_cells(rst: str) -> list[str]:
    """The text of every cell of the page's list-tables (header cells included)."""
    cells, inside = [], False
    for line in rst.splitlines():
        if line.startswith(".. list-table::"):
            inside = True
        elif inside and line and not line.startswith(" "):
            inside = False
        elif inside and (cell := re.match(r"   (?:\* |  )-(?: (.*))?$", line)):
            cells.append(cell.group(1) or "")
        elif inside and line.startswith("       ") and cells:
            cells[-1] += " " + line.strip()
    return cells


def findings_problems(rst: str) -> list[str]:
    """What makes a findings page a raw dump rather than a report (issue 58): a table cell
    with a number of more than `MAX_DIGITS` significant digits, a "nan" anywhere (a value
    not given must say why), a figure captioned by its file name or not at all."""
    problems = [f"number in a table with more than {MAX_DIGITS} significant digits: "
                f"{n.group(0)!r}"
                for c in table_cells(rst) for n in NUMBER.finditer(c)
                if significant_digits(n.group(1), n.group(2)) > MAX_DIGITS]
    problems += [f"'nan' in {line.strip()!r}" for line in rst.splitlines()
                 if re.search(r"\bnan\b", line, flags=re.I)]
    for _, path, caption in re.findall(r"^( *)\.\. figure:: (\S+)\n(?:\1   :.*\n)*\n"
                                       r"(?:\1   (.*))?", rst, flags=re.M):
        bare = caption.strip("`* ")
        if not bare or bare == Path(path).name or re.fullmatch(r"[\w.+-]+\.(png|gif|svg)",
                                                                bare):
            problems.append(f"figure {path} captioned {caption!r}: not what it shows")
    return problems


def test_the_findings_page_reads_like_the_report(reported, tmp_path, monkeypatch):
    """Issue 58: the findings page dumped stored CSV files — 17-digit floats in rad and m,
    "nan" cells, figures captioned by their file names.  Generated from a stored results
    folder, it opens with the report's answer (one sentence per arm and plant), then its
    tables in the report's units and rounding and its figures with their captions; the
    lab arm's and the kinematics' parts, not stored, say how to produce them.  Known-bad:
    the old page's dump of the claims' records and a figure captioned by its file."""
    from flexarm_docs import findings
    from flexarm_docs.rst import list_table
    from validation.batch.store.folder import ResultStore
    from validation.batch.store.resimulate import every_signal
    from validation.report.record import load_record
    from validation.verdicts.claims import claim_columns, claims_records
    monkeypatch.setenv("FLEXARM_FINDINGS", str(reported))
    monkeypatch.setenv("FLEXARM_FINDINGS_LAB", str(tmp_path / "lab"))
    kinematics = tmp_path / "kinematics"
    kinematics.mkdir()
    # An attribution as `flexarm attribute` stores it: SI units, every digit a float has.
    (kinematics / "attribution.csv").write_text(
        "study,metric,factor,contribution,share\n"
        + "".join(f"pbc+smo-paper@rest,{metric},{factor},{value!r},\n"
                  for metric, values in (("track_rms", (0.009627723588051751,
                                                        0.0041372958823005, 0.00549042770575125)),
                                         ("vib_rms", (0.0014273958235833857, float("nan"),
                                                      float("nan"))))
                  for factor, value in zip(("total", "kinematics", "plant"), values)))
    monkeypatch.setenv("FLEXARM_FINDINGS_KINEMATICS", str(kinematics))
    docs = tmp_path / "docs"
    page = findings.render(docs)
    assert findings_problems(page) == []
    record = load_record(reported)
    answers = "".join(f"* {line}\n" for line in record["answers"])
    assert len(record["answers"]) == 2  # one arm on two plants
    assert page.split("\n\n", 2)[2].startswith(answers + "* No report of the lab arm at ")
    assert "flexarm reproduce-paper --lab --no-stability" in page
    kinematics_cells = table_cells(page.split("its kinematics\n")[1])
    assert {"tracking error, RMS [mrad]", "9.63", "85.9 %", "vibration RMS [mm]", "1.43",
            "— (diverged)"} <= set(kinematics_cells)
    shown = re.findall(r"^ *\.\. figure:: /_generated/findings/paper/(\S+)", page, flags=re.M)
    assert len(shown) == 5 and all((docs / "_generated" / "findings" / "paper" / f).is_file()
                                   for f in shown)
    assert "mrad" in " ".join(table_cells(page))  # the report's units, not rad and m

    store = ResultStore(reported)
    records = claims_records(claim_columns(store.rows(), functools.partial(every_signal, store)))
    dump = list_table(list(records[0]), [[str(v) for v in r.values()] for r in records])
    dump += f".. figure:: /_generated/findings/{shown[0]}\n   :width: 100%\n\n   ``{shown[0]}``\n"
    problems = findings_problems(dump)
    assert any("number in a table" in p for p in problems)
    assert any(p.startswith("'nan'") for p in problems)
    assert any("not what it shows" in p for p in problems)


def test_the_site_ships_its_math_renderer():
    """Issue 47: MathJax came from a CDN (raw LaTeX offline).  The site loads the file the
    build copies from the pinned package (constraints.txt), a path inside _static."""
    from flexarm_docs.mathjax import COMPONENT
    assert not re.match(r"\w+://", COMPONENT) and COMPONENT.endswith(".js")
    pins = (ROOT / "constraints.txt").read_text()
    assert re.search(r"^django-static-mathjax==", pins, flags=re.M)
    # sphinx-gallery's computation-time pages load jQuery and DataTables from CDNs
    assert '"write_computation_times": False' in (DOCS / "conf.py").read_text()


EXAMPLES = sorted((DOCS / "examples").glob("plot_*.py"))


def test_the_gallery_has_eight_examples():
    assert len(EXAMPLES) >= 8


@pytest.mark.slow
@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.stem)
def test_gallery_example_runs(example, tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(example)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
