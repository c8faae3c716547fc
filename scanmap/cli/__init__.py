"""The `scanmap` command line.

Each subcommand lives in its own module under `scanmap.cli.commands` and defines
`register(subparsers)`, which adds its parser and sets `func(args) -> int`. Modules are
discovered, so adding a command never edits this file.
"""

from __future__ import annotations

import os

# One BLAS thread, set before NumPy and SciPy load their OpenBLAS (it reads this once, when
# it loads). A command parallelises by scans, in its own threads; the few BLAS products it
# makes are small (N x 3 by 3 x 3), and each library's helper thread, woken by the
# libraries' own start-up calls, then spins about 0.1 s for more work: 0.3 s of CPU per
# `scanmap map`, partly on the core the mapping needs. A user's setting is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import atexit
import gc
import importlib
import importlib.machinery
import importlib.util
import pkgutil
import sys
import threading
from typing import NoReturn

from scanmap.cli import commands
from scanmap_driver import ScanmapError, __version__


def build_parser() -> argparse.ArgumentParser:
    """The parser with every subcommand found in `scanmap.cli.commands`."""
    parser = argparse.ArgumentParser(
        prog="scanmap",
        description="Mapping and obstacle avoidance with the inexpensive rotating "
                    "laser-line 3D scanner.")
    parser.add_argument("--version", action="version", version=f"scanmap {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None
         ) -> int:
    """Run the command line (with `parser`, default `build_parser()`); returns the
    process exit code."""
    parser = parser or build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except ScanmapError as exc:
        print(f"scanmap: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("scanmap: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and closed early
        sys.stderr.close()
        return 0


def exit_without_collecting(code: int) -> NoReturn:
    """End the process with `code` after the `atexit` handlers, the output flushed, but
    without the interpreter's teardown (`os._exit`).

    Once a command has loaded its Numba kernels, the teardown is slow: its garbage
    collections walk their many type objects, and clearing the modules releases every
    kernel's LLVM code. After `scanmap map` had printed its last line the prompt came back
    0.25-0.3 s later, 0.06 s with the collections skipped (`gc.freeze`), 0.02 s with the
    whole teardown skipped; the operating system frees the memory. A thread still
    running (never one of scanmap's: commands join theirs) gets the normal exit, which
    waits for it. Only for a process's last step.
    """
    if any(t.is_alive() and not t.daemon for t in threading.enumerate()
           if t is not threading.main_thread()):
        sys.exit(code)
    atexit._run_exitfuncs()  # what a normal exit runs first (logging's flush among them)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader gone (`| head`), or `main` closed it
            pass
    os._exit(code)


def load_blas_modules_alone() -> None:
    """Load SciPy's BLAS and LAPACK modules for Cython (`scipy.linalg.cython_blas`,
    `cython_lapack`) without the `scipy.linalg` package around them, for Numba.

    Numba imports the first when it sets up its compiler (the first kernel a command
    calls, cached or not) to check that BLAS is there, and the second when it loads a
    kernel that calls LAPACK (`np.linalg`). Python then runs `scipy.linalg`'s `__init__`,
    which loads SciPy's array-API layer and through it `numpy.f2py` and `numpy.testing`:
    0.1 s of `scanmap map`'s 2.1 s, on the path every scan waits for, for nothing a
    command uses. Each extension module alone loads in 2 ms. They are the same modules
    under their own names, so Numba's calls and a later `import scipy.linalg` use them;
    only the attributes `scipy.linalg.cython_blas` and `cython_lapack` stay unbound
    (Numba, Cython and `from scipy.linalg import cython_blas` look the modules up by
    name). Where SciPy lays its files out otherwise, nothing is done and Numba imports
    the package as before. For a process's start, from `run`.
    """
    if "scipy.linalg" in sys.modules:
        return
    try:
        import scipy  # the package Numba's check imports anyway (15 ms)
    except ImportError:  # Numba's own check then reports it
        return

    folder = os.path.join(os.path.dirname(scipy.__file__), "linalg")
    for stem in ("cython_blas", "cython_lapack"):
        name = f"scipy.linalg.{stem}"
        paths = [os.path.join(folder, stem + suffix)
                 for suffix in importlib.machinery.EXTENSION_SUFFIXES]
        path = next((p for p in paths if os.path.isfile(p)), None)
        if name in sys.modules or path is None:
            continue
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[name] = module


def run() -> NoReturn:
    """The `scanmap` executable: `main`, then `exit_without_collecting`.

    The modules every command imports live as long as the process, so they are frozen
    (`gc.freeze`) before the command runs: the full collections a command triggers then
    skip them. In `scanmap map` the one that fell while its Numba kernels loaded, on the
    path every scan waits for, took 47 ms, and 13 ms with this.
    """
    load_blas_modules_alone()
    parser = build_parser()
    gc.freeze()
    exit_without_collecting(main(parser=parser))


if __name__ == "__main__":
    run()
