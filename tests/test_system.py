"""What a fresh machine needs: every installed package pinned in constraints.txt (the set
`make test` installs), and a missing system library named in one line with its fix."""
import subprocess
import sys
import textwrap
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _pins() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            pins[name.lower().replace("_", "-")] = version
    return pins


def test_every_installed_package_is_pinned():
    pins = _pins()
    installed = {d.metadata["Name"].lower().replace("_", "-") for d in metadata.distributions()}
    installed.discard("flexarm-validation")
    assert installed - set(pins) == set(), "installed but not pinned (run make lock)"
    assert {"numpy", "scipy", "numba", "exudyn", "pip", "setuptools"} <= set(pins)


def test_a_missing_system_library_is_one_line_naming_the_fix(tmp_path):
    # What Exudyn 1.13.6 raises on a Debian image without libgl1 (its own wording).
    fake = tmp_path / "exudyn"
    fake.mkdir()
    (fake / "__init__.py").write_text(textwrap.dedent('''
        raise ImportError("Exudyn could not import its compiled module. Tried, in order:\\n"
                          "  .exudynCPP  ->  libGL.so.1: cannot open shared object file: "
                          "No such file or directory")
    '''))
    proc = subprocess.run([sys.executable, "-m", "validation.cli", "modes"], cwd=tmp_path,
                          env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"},
                          capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "libGL.so.1" in proc.stderr and "apt-get install libgl1" in proc.stderr
    assert list(tmp_path.iterdir()) == [fake]  # nothing written


def test_an_ordinary_import_error_is_not_called_a_missing_library():
    from validation.cli.system import missing_library
    assert missing_library(ImportError("No module named 'mylab'")) is None
    assert "libX11.so.6" in missing_library(ImportError(
        "libX11.so.6: cannot open shared object file: No such file or directory"))
