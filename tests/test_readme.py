"""Every command and snippet of the README runs as written."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)


def files_in_blocks() -> dict[str, str]:
    """Code blocks whose first line is a comment naming a file: "# mylab/control.py"."""
    out = {}
    for _, body in BLOCKS:
        first = body.splitlines()[0]
        m = re.fullmatch(r"# ([\w./-]+\.(?:py|toml))", first.strip())
        if m:
            out[m.group(1)] = body
    return out


SNIPPETS = [body for lang, body in BLOCKS if lang == "python"
            and not re.match(r"# [\w./-]+\.py\n", body)]


@pytest.mark.parametrize("snippet", SNIPPETS, ids=[f"python{i}" for i in range(len(SNIPPETS))])
def test_python_snippets_run(snippet, tmp_path):
    proc = subprocess.run([sys.executable, "-c", snippet], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_bring_your_own_example_runs_as_written(tmp_path):
    files = files_in_blocks()
    assert {"mylab/control.py", "byo.toml"} <= set(files)
    for name in ("mylab/control.py", "byo.toml"):
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(files[name])
    commands = next(body for lang, body in BLOCKS if lang == "sh" and "byo.toml" in body)
    flexarm = [sys.executable, "-m", "validation.cli"]
    for line in commands.strip().splitlines():
        args = line.split()
        if args[0] == "touch":
            (tmp_path / args[1]).touch()
            continue
        assert args[0] == "flexarm"
        proc = subprocess.run(flexarm + args[1:], cwd=tmp_path, capture_output=True,
                              text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "ok" in proc.stdout or "max |e1|" in proc.stdout


def test_readme_campaign_example_is_valid(tmp_path):
    """The complete campaign example parses, checks and expands."""
    from validation.batch.campaign import expand, load_campaign
    block = README.split("```toml\n# my.toml")[1].split("```")[0]
    text = "# my.toml" + block.replace('include = "campaigns/base.toml"',
                                       f'include = "{ROOT / "campaigns" / "base.toml"}"')
    (tmp_path / "my.toml").write_text(text)
    runs = expand(load_campaign(tmp_path / "my.toml"))
    assert len(runs) == 2 * 4 * 3 * 2 + 8
    assert {r.scenario.plant.kind for r in runs} == {"reduced", "exudyn"}
    assert runs[0].scenario.disturbances[0].kind == "pulse"


def test_readme_commands_name_real_flags():
    """Every `flexarm <command> --flag` in the README's shell blocks exists."""
    from validation.cli import build_parser
    parser = build_parser()
    subcommands = parser._subparsers._group_actions[0].choices
    for lang, body in BLOCKS:
        if lang != "sh":
            continue
        for line in body.splitlines():
            words = line.split("#")[0].split()
            if len(words) < 2 or words[0] != "flexarm" or words[1].startswith("-"):
                continue
            sub = subcommands[words[1]]
            if words[1] == "baseline":
                sub = sub._subparsers._group_actions[0].choices[words[2].split("|")[0]]
            known = {o for a in sub._actions for o in a.option_strings}
            for w in words:
                flag = w.strip("[]").split("=")[0]
                if flag.startswith("--"):
                    assert flag in known, f"{line!r}: {flag} is not a flag of {words[1]}"
