"""The ``flexarm`` command line: output and one-line errors with exit status 2."""
import subprocess
import sys

import pytest

from validation.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("flexarm-validation ")


def test_modes_prints_table1_frequencies(capsys):
    assert main(["modes", "--table1", "--theta2", "0", "1.5708"]) == 0
    out = capsys.readouterr().out
    assert "0.6316" in out and "3.8313" in out and "2.2359" in out  # locked / free at θ2 = 0
    assert out.count("joints locked") == 2 and "Table 1" in out


def test_modes_reads_params_toml(tmp_path, capsys):
    path = tmp_path / "arm.toml"
    path.write_text("[params]\nMp = 0.5\n")
    assert main(["modes", "--params", str(path)]) == 0
    assert str(path) in capsys.readouterr().out


def test_modes_compare_prints_fe_next_to_reduced(capsys):
    assert main(["modes", "--table1", "--compare", "--theta2", "0"]) == 0
    out = capsys.readouterr().out
    assert out.count("FE  ") == 2 and out.count("gap [%]") == 2
    assert "31.4327" in out  # FE free 3rd mode (the reduced model's truncation gap)


@pytest.mark.parametrize("args, text", [
    (["modes", "--compare", "--elements", "0"], "--elements: must be in 1..64"),
    (["modes", "--table1", "--params", "x.toml"], "exclude each other"),
    (["modes", "--modes-per-link", "5", "2"], "--modes-per-link must be two integers"),
    (["modes", "--params", "/nonexistent/arm.toml"], "cannot read"),
    (["modes", "--params", "{bad_field}"], "params.Lx: unknown parameter"),
    (["modes", "--params", "{negative}"], "params.EI1 must be > 0"),
    (["modes", "--params", "{not_toml}"], "invalid TOML"),
    (["nonsense"], "invalid choice"),
])
def test_bad_input_one_line_exit_2(tmp_path, args, text):
    files = {"bad_field": "Lx = 1.0\n", "negative": "EI1 = -3.0\n", "not_toml": "EI1 = = 3\n"}
    for key, content in files.items():
        (tmp_path / f"{key}.toml").write_text(content)
    args = [a.format(**{k: str(tmp_path / f"{k}.toml") for k in files}) for a in args]
    proc = subprocess.run([sys.executable, "-m", "validation.cli", *args],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error:"), proc.stderr
    assert text in lines[0]
