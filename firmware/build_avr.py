"""Build the scanmap_motor sketch for an Arduino Uno/Nano (ATmega328P, 16 MHz) without the
Arduino IDE, and the simavr runner that runs it with UART0 on a pseudo-terminal.

The ELF is built the way the Arduino IDE builds it (flags from the core's platform.txt,
without LTO): the sketch becomes a .cpp with `#include <Arduino.h>` prepended, and is linked
with the Arduino AVR core's .c/.cpp/.S files. Needs the Debian packages gcc-avr, avr-libc
and arduino-core-avr; the runner needs a C compiler (gcc) and simavr's libsimavr-dev
(scripts/setup.sh installs them all).

    python firmware/build_avr.py [--drive dc|step] [--out DIR]   # prints the ELF's path

The tests (tests/scanmap_driver/test_motor_firmware.py) call `build_elf` and
`build_runner` once per session.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
SKETCH = HERE / "scanmap_motor" / "scanmap_motor.ino"
RUNNER_SOURCE = HERE / "simavr" / "uart_pty_runner.c"
ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")  # Debian arduino-core-avr
MCU = "atmega328p"
F_CPU = 16_000_000
DRIVES = {"dc": 1, "step": 2}  # the sketch's DRIVE_DC, DRIVE_STEP

COMMON = ["-g", "-Os", "-ffunction-sections", "-fdata-sections", f"-mmcu={MCU}",
          f"-DF_CPU={F_CPU}L", "-DARDUINO=10807", "-DARDUINO_AVR_UNO", "-DARDUINO_ARCH_AVR"]
FLAGS = {
    ".c": ["avr-gcc", "-w", "-std=gnu11"],
    # Debian's WString.cpp wants DECIMAL_DIG, which avr-gcc 5's <float.h> only gives C99:
    # the same value for C++.
    ".cpp": ["avr-g++", "-w", "-std=gnu++11", "-fpermissive", "-fno-exceptions",
             "-fno-threadsafe-statics", "-DDECIMAL_DIG=__DECIMAL_DIG__"],
    ".S": ["avr-gcc", "-x", "assembler-with-cpp"],
}
# The sketch itself must compile without a warning on the real target (16-bit int!).
SKETCH_FLAGS = ["avr-g++", "-std=gnu++11", "-fno-exceptions", "-fno-threadsafe-statics",
                "-Wall", "-Wextra", "-Werror"]


class ToolchainError(RuntimeError):
    """A tool or package of the AVR toolchain is missing; the message says which."""


def _require(tool: str, package: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise ToolchainError(f"{tool} not found: install the Debian package {package} "
                             "(scripts/setup.sh does)")
    return path


def _run(command: list[str]) -> None:
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)}\nfailed:\n{done.stderr}")


def _compile(source: Path, obj: Path, includes: list[str], flags: list[str] | None = None
             ) -> Path:
    _run([*(flags or FLAGS[source.suffix]), "-c", *COMMON, *includes, str(source),
          "-o", str(obj)])
    return obj


def build_core(out: Path) -> Path:
    """Compile the Arduino AVR core into `out`/core.a (once; reused if present)."""
    _require("avr-gcc", "gcc-avr")
    core = ARDUINO_AVR / "cores" / "arduino"
    if not (core / "Arduino.h").exists() or not (ARDUINO_AVR / "variants").exists():
        raise ToolchainError(f"no Arduino AVR core in {ARDUINO_AVR}: install the Debian "
                             "package arduino-core-avr (scripts/setup.sh does)")
    if not Path("/usr/lib/avr/include/avr/io.h").exists():
        raise ToolchainError("no avr/io.h: install the Debian package avr-libc")
    archive = out / "core.a"
    if archive.exists():
        return archive
    includes = [f"-I{core}", f"-I{ARDUINO_AVR / 'variants' / 'standard'}"]
    sources = sorted(p for p in core.iterdir() if p.suffix in FLAGS)
    objdir = out / "core"
    objdir.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(max_workers=2) as pool:
        objects = list(pool.map(
            lambda src: _compile(src, objdir / f"{src.name}.o", includes), sources))
    _run([_require("avr-ar", "binutils-avr"), "rcs", str(archive), *map(str, objects)])
    return archive


def build_elf(out: Path, drive: str = "dc", sketch: Path = SKETCH) -> Path:
    """The sketch for an ATmega328P at 16 MHz as `out`/scanmap_motor_<drive>.elf."""
    out.mkdir(parents=True, exist_ok=True)
    elf = out / f"{sketch.stem}_{drive}.elf"
    if elf.exists():
        return elf
    archive = build_core(out)
    cpp = out / f"{sketch.stem}_{drive}.ino.cpp"
    cpp.write_text(f'#include <Arduino.h>\n#line 1 "{sketch}"\n{sketch.read_text()}')
    includes = [f"-I{ARDUINO_AVR / 'cores' / 'arduino'}",
                f"-I{ARDUINO_AVR / 'variants' / 'standard'}", f"-DDRIVE={DRIVES[drive]}"]
    obj = _compile(cpp, out / f"{cpp.name}.o", includes, SKETCH_FLAGS)
    _run(["avr-gcc", "-w", "-Os", "-g", "-Wl,--gc-sections", f"-mmcu={MCU}", "-o", str(elf),
          str(obj), str(archive), "-lm"])
    return elf


def build_runner(out: Path, source: Path = RUNNER_SOURCE) -> Path:
    """Compile the simavr UART-to-pty runner (firmware/simavr) with the system C compiler."""
    compiler = _require("cc", "gcc")
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        raise ToolchainError("no simavr headers: install the Debian package libsimavr-dev "
                             "(scripts/setup.sh does)")
    out.mkdir(parents=True, exist_ok=True)
    binary = out / source.stem
    if not binary.exists():
        _run([compiler, "-O2", "-Wall", "-Wextra", "-Werror", "-I/usr/include/simavr",
              str(source), "-o", str(binary), "-lsimavr", "-lutil"])
    return binary


def main() -> None:
    """Command line: build the ELF (and optionally the runner) and print their paths."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drive", choices=sorted(DRIVES), default="dc")
    parser.add_argument("--out", type=Path, default=None,
                        help="build directory (default: a new temporary directory)")
    parser.add_argument("--runner", action="store_true", help="also build the simavr runner")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="scanmap_avr_"))
    print(build_elf(out, args.drive))
    if args.runner:
        print(build_runner(out))


if __name__ == "__main__":
    main()
