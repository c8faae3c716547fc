"""The command line's shell: --help and --version."""

from __future__ import annotations

import os
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
    """`run` skips the interpreter's teardown, not the exit code, what was printed (a
    command that fails still says so), the atexit handlers or a thread still running."""
    missing = tmp_path / "no_recording"
    result = subprocess.run([sys.executable, "-m", "scanmap", "map", str(missing), "--out",
                             str(tmp_path / "map")], capture_output=True, text=True)
    assert result.returncode == 1
    assert f"scanmap: error: {missing}" in result.stderr
    script = ("import atexit; from scanmap.cli import exit_without_collecting; "
              "atexit.register(print, 'atexit ran'); print('kept', end=' '); "
              "exit_without_collecting(3)")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert (result.returncode, result.stdout) == (3, "kept atexit ran\n")
    # output piped into a reader that closed early (`| head`): the code, no traceback
    script = ("import sys; from scanmap.cli import exit_without_collecting\n"
              "try:\n    for i in range(100000): print('line', i)\n"
              "except BrokenPipeError:\n    sys.stderr.close()\n"
              "exit_without_collecting(0)")
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    process.stdout.read(10)
    process.stdout.close()
    assert (process.wait(), process.stderr.read()) == (0, b"")
    # a thread still running is waited for (its output is not lost)
    script = ("import threading, time; from scanmap.cli import exit_without_collecting; "
              "threading.Thread(target=lambda: (time.sleep(0.3), print('thread done'))).start(); "
              "exit_without_collecting(4)")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert (result.returncode, result.stdout) == (4, "thread done\n")


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: scanmap" in capsys.readouterr().out


def test_reexports_driver_types():
    from scanmap import Scan
    from scanmap_driver.scan import Scan as DriverScan

    assert Scan is DriverScan


def test_the_package_loads_its_names_on_first_use():
    """`import scanmap` imports no NumPy (the command line sets the BLAS threads before
    it loads); each public name then comes from its module, and `dir` lists them all."""
    code = ("import sys, scanmap; print('numpy' in sys.modules); "
            "print(all(getattr(scanmap, n) is not None for n in scanmap.__all__)); "
            "print(set(scanmap.__all__) <= set(dir(scanmap)))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.split() == ["False", "True", "True"]
    from scanmap.mapping import Mapper
    from scanmap.navigation import segment

    assert scanmap.Mapper is Mapper and scanmap.segment is segment
    with pytest.raises(AttributeError, match="no attribute 'Mappr'"):
        scanmap.Mappr  # noqa: B018


BLAS_PRODUCT = ("import os, numpy as np; a = np.ones((600, 600)); a @ a; "
                "print(os.environ.get('OPENBLAS_NUM_THREADS'), "
                "len(os.listdir('/proc/self/task')))")


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads in /proc")
def test_the_command_line_runs_blas_on_one_thread_unless_told_otherwise():
    """A product large enough for OpenBLAS to share starts no helper thread in a process
    that imported the command line first (one thread: the main one), as a plain NumPy
    process does; a user's OPENBLAS_NUM_THREADS is kept."""
    def run(env_value: str | None) -> list[str]:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
        if env_value is not None:
            env["OPENBLAS_NUM_THREADS"] = env_value
        result = subprocess.run([sys.executable, "-c", "import scanmap.cli; " + BLAS_PRODUCT],
                                capture_output=True, text=True, check=True, env=env)
        return result.stdout.split()

    assert run(None) == ["1", "1"]
    kept, threads = run("2")
    assert kept == "2" and int(threads) > 1  # helpers started: the count can tell


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


NUMBA_LINEAR_ALGEBRA = """
import sys
import numpy as np
from numba import njit
from scanmap.cli import load_blas_modules_alone

load_blas_modules_alone()

@njit(cache=False)
def solve_and_multiply(a, b):
    return np.linalg.solve(a, b), a @ b

a = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]])
b = np.array([1.0, 2.0, 3.0])
x, product = solve_and_multiply(a, b)
print(int("scipy.linalg" in sys.modules), float(np.abs(a @ x - b).max()),
      float(np.abs(product - np.array([6.0, 10.0, 8.0])).max()))
import scipy.linalg
print(float(np.abs(scipy.linalg.solve(a, b) - x).max()))
"""


def test_numba_s_blas_and_lapack_work_without_scipy_linalg_s_package():
    """After `load_blas_modules_alone` (the executable's start), a kernel's LAPACK solve
    and BLAS product are right (against the closed form) while `scipy.linalg`'s package
    stays unloaded; importing it later still works and agrees."""
    result = subprocess.run([sys.executable, "-c", NUMBA_LINEAR_ALGEBRA], capture_output=True,
                            text=True, check=True)
    first, second = result.stdout.splitlines()
    loaded, residual, product_error = first.split()
    assert loaded == "0"
    assert float(residual) < 1e-12 and float(product_error) == 0.0
    assert float(second) < 1e-12
