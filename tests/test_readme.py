"""Every command and snippet of the README runs as written (the docs pages' examples:
tests/test_docs.py)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)


SNIPPETS = [body for lang, body in BLOCKS if lang == "python"
            and not re.match(r"# [\w./-]+\.py\n", body)]


@pytest.mark.parametrize("snippet", SNIPPETS, ids=[f"python{i}" for i in range(len(SNIPPETS))])
def test_python_snippets_run(snippet, tmp_path):
    proc = subprocess.run([sys.executable, "-c", snippet], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]


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
