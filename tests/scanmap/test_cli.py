"""The command line's shell: --help and --version."""

from __future__ import annotations

import subprocess
import sys

import pytest

import scanmap
from scanmap.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"scanmap {scanmap.__version__}"


def test_help_lists_subcommands_and_runs_as_module():
    result = subprocess.run([sys.executable, "-m", "scanmap", "--help"], capture_output=True,
                            text=True, check=True)
    assert "usage: scanmap" in result.stdout


def test_the_executable_exits_with_the_command_s_code_and_its_output(tmp_path):
    """`run` skips the shutdown's garbage collections, not the exit code or what was
    printed (a command that fails still says so)."""
    missing = tmp_path / "no_recording"
    result = subprocess.run([sys.executable, "-m", "scanmap", "map", str(missing), "--out",
                             str(tmp_path / "map")], capture_output=True, text=True)
    assert result.returncode == 1
    assert f"scanmap: error: {missing}" in result.stderr
    script = "from scanmap.cli import exit_without_collecting; print('kept'); " \
             "exit_without_collecting(3)"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert (result.returncode, result.stdout) == (3, "kept\n")


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: scanmap" in capsys.readouterr().out


def test_reexports_driver_types():
    from scanmap import Scan
    from scanmap_driver.scan import Scan as DriverScan

    assert Scan is DriverScan


HEAVY_AT_START = ("open3d", "scipy.optimize", "scipy.ndimage", "scipy.special")


def test_the_command_line_starts_without_open3d_or_scipy_s_heavy_parts():
    """Only simulating and ray-cast evaluation need Open3D (about 1 s to import), only
    calibration scipy.optimize (0.2 s), only building a truth raster scipy.ndimage (with
    scipy.special, 0.3 s): building the command line (every command's options) and
    mapping's modules must load none of them."""
    code = ("import sys; from scanmap.cli import build_parser; build_parser(); "
            "import scanmap.pipelines.offline; "
            f"print(*[m in sys.modules for m in {HEAVY_AT_START!r}])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.split() == ["False"] * len(HEAVY_AT_START)
