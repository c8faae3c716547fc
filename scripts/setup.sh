#!/usr/bin/env bash
# Set up scanmap on a fresh machine (idempotent; fast when nothing changed):
#   1. the system library libusb-1.0-0 that Open3D loads, and the toolchains that build
#      and run the motor firmware in the tests (g++ for the host build; avr-gcc, avr-libc,
#      the Arduino AVR core and simavr for the ATmega328P build),
#   2. a virtual environment in .venv,
#   3. the package (editable) with its dev, peers, bench, ros and cluster extras.
# Needs Python >= 3.11 with pip; apt for the system packages (root, or sudo without a
# password; otherwise it prints the exact command to run).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}

# Waits up to 10 minutes for another apt or dpkg (an unattended upgrade, a second
# set-up) to release its lock instead of failing at once.
APT_WAIT=(-o DPkg::Lock::Timeout=600)
apt_install() {
  if [ "$(id -u)" = 0 ]; then
    apt-get "${APT_WAIT[@]}" update -qq \
      && DEBIAN_FRONTEND=noninteractive apt-get "${APT_WAIT[@]}" install -y -qq "$@"
  elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    sudo apt-get "${APT_WAIT[@]}" update -qq \
      && sudo DEBIAN_FRONTEND=noninteractive apt-get "${APT_WAIT[@]}" install -y -qq "$@"
  else
    echo "scanmap setup: please run:  sudo apt-get install -y $*" >&2
    exit 1
  fi
}

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "scanmap setup: installing libusb-1.0-0 (needed by Open3D)"
  apt_install libusb-1.0-0
fi

# The motor firmware's tests (tests/scanmap_driver/test_motor_firmware.py) build the sketch
# with g++ and for the ATmega328P (firmware/build_avr.py), and run it in simavr.
firmware_packages=(gcc g++ gcc-avr binutils-avr avr-libc arduino-core-avr simavr libsimavr-dev)
missing=()
for package in "${firmware_packages[@]}"; do
  dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "ok installed" ||
    missing+=("$package")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "scanmap setup: installing ${missing[*]} (to build and simulate the motor firmware)"
  apt_install "${missing[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  if ! "$PYTHON" -m venv --help >/dev/null 2>&1; then
    apt_install python3-venv
  fi
  echo "scanmap setup: creating .venv"
  "$PYTHON" -m venv .venv
fi

stamp=.venv/.scanmap-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "scanmap setup: installing scanmap and its dependencies into .venv"
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -e ".[dev,peers,bench,ros,cluster]"
  echo "$want" > "$stamp"
fi
.venv/bin/python -c "import open3d, cv2, numba, scanmap" || {
  echo "scanmap setup: the installed environment does not import; see the errors above" >&2
  exit 1
}

# Compile every Numba kernel of the main job into its cache beside the sources, so that
# the first run is as fast as the tenth (a few seconds when the cache is already warm).
echo "scanmap setup: compiling the kernels (once; later runs load them)"
.venv/bin/scanmap warm-up

# Python's bytecode of scanmap too: where PYTHONDONTWRITEBYTECODE is set (containers, CI)
# every run would otherwise compile its hundred-odd modules again, about 0.3 s a start.
.venv/bin/python -m compileall -q -j 0 scanmap scanmap_driver examples benchmarks
