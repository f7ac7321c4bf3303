"""The documentation stays true (like python-control's doc/test_sphinxdocs.py): every
public name is in the API reference with numpydoc sections, the configuration and metric
references cover what the code defines, the examples in the pages run as written, the
commands they show exist, and the gallery's examples run (slow: ``make docs`` runs them
too).  Runs without the docs extra: the docstrings are read by the same small reader the
site's generators use."""
import dataclasses
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
        proc = subprocess.run([sys.executable, "-m", "validation.cli", *args[1:]],
                              cwd=tmp_path, capture_output=True, text=True, timeout=600)
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
