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


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: scanmap" in capsys.readouterr().out


def test_reexports_driver_types():
    from scanmap import Scan
    from scanmap_driver.scan import Scan as DriverScan

    assert Scan is DriverScan


def test_the_command_line_starts_without_open3d_or_the_optimisers():
    """Only simulating and ray-cast evaluation need Open3D (about 1 s to import), only
    calibration scipy.optimize (0.2 s): building the command line (every command's
    options) must load neither."""
    code = ("import sys; from scanmap.cli import build_parser; build_parser(); "
            "print('open3d' in sys.modules, 'scipy.optimize' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.split() == ["False", "False"]
