# Sourced by run.sh and test.sh: make or reuse the venv "$VENV" and install qrfield into it, again
# only when pyproject.toml (or what is installed) changed. Works from any current folder: the
# repository is found from this file's own path, and the current folder is never changed (the
# caller's relative paths stay the caller's).
#
# The caller sets QRFIELD_INSTALL to what it needs:
#   app  (run.sh)   the core; plus the app's extra "gui" (PySide6, pyqtgraph) where a display is
#                   possible or the app is asked for (QRFIELD_GUI=1 forces it, QRFIELD_GUI=0 never)
#   dev  (test.sh)  the core, "gui" and "dev" (pytest, pytest-qt, hypothesis, ruff)
#
# Machines:
#   - Raspberry Pi OS, 64-bit: the venv sees the system's site-packages, so that the OS's picamera2
#     (apt: python3-picamera2) is importable, and numpy stays 1.x there: Bookworm's picamera2 (its
#     simplejpeg) is built for numpy 1.x and fails to import under numpy 2. pip then picks
#     opencv-python-headless 4.11 (4.12 and later need numpy 2).
#   - 32-bit ARM (armv7l, armv6l: 32-bit Raspberry Pi OS, also on a 64-bit kernel): PyPI has no
#     wheels of numpy, OpenCV, zxing-cpp or PySide6 there, and pip would try to compile them for
#     hours. The app needs 64-bit Raspberry Pi OS; the headless commands run on the OS's own
#     packages: a venv with the system site-packages and qrfield installed with --no-deps
#     (docs/install.md). QRFIELD_OS_PACKAGES=1 takes that path on any Debian machine (to test it).
# Environment: QRFIELD_VENV (default: .venv in the repository; a relative path is the caller's),
# PYTHON (default python3).

QRFIELD_REPO="$(cd -- "$(dirname -- "${BASH_SOURCE[0]}")/.." && pwd -P)"
VENV="${QRFIELD_VENV:-$QRFIELD_REPO/.venv}"
PYTHON="${PYTHON:-python3}"
QRFIELD_INSTALL="${QRFIELD_INSTALL:-app}"
#: The OS packages of the headless path (Debian 12 / Raspberry Pi OS Bookworm: numpy 1.24,
#: OpenCV 4.6, zxing-cpp 1.4, pyqtgraph 0.13.1, pyserial 3.5).
QRFIELD_OS_APT="python3-numpy python3-opencv python3-zxing-cpp python3-pyqtgraph python3-serial python3-venv"

_say() { echo "qrfield: $*" >&2; }

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  _say "qrfield needs Python 3.11 or newer; found: $("$PYTHON" --version 2>&1)"
  exit 1
fi

on_pi=false
if [ -f /etc/rpi-issue ] || grep -qs "Raspberry Pi" /proc/device-tree/model; then
  on_pi=true
fi
# 32-bit ARM is told by the Python that will run qrfield, not by the kernel (`uname -m` says aarch64
# on 32-bit Raspberry Pi OS with its default 64-bit kernel).
arm32=false
if "$PYTHON" -c 'import platform, struct, sys
m = platform.machine().lower()
sys.exit(not (m.startswith("arm") or m == "aarch64") or struct.calcsize("P") != 4)' 2>/dev/null; then
  arm32=true
fi
os_packages=false
if $arm32 || [ "${QRFIELD_OS_PACKAGES:-0}" = 1 ]; then
  os_packages=true
fi

_display_possible() {
  case "${QRFIELD_GUI:-auto}" in
    1 | yes | true) return 0 ;;
    0 | no | false) return 1 ;;
  esac
  [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ] && return 0
  case "$(uname -s)" in Darwin | MINGW* | MSYS* | CYGWIN*) return 0 ;; esac
  # A desktop is installed (Raspberry Pi OS with desktop, any Linux desktop) even if this shell has
  # none (ssh): the app may be started there later.
  compgen -G "/usr/share/xsessions/*.desktop" >/dev/null && return 0
  compgen -G "/usr/share/wayland-sessions/*.desktop" >/dev/null && return 0
  return 1
}

if $os_packages; then
  if $arm32; then
    _say "this is 32-bit ARM ($("$PYTHON" -c 'import platform; print(platform.machine())') with a 32-bit Python):" \
      "the bench app needs 64-bit Raspberry Pi OS (PySide6 has no 32-bit ARM build), and PyPI has no" \
      "numpy, OpenCV or zxing-cpp for it. The headless commands (qrfield run, solve, marker, ...) can" \
      "run on the OS's own packages."
  fi
  missing=()
  "$PYTHON" -c 'import numpy' 2>/dev/null || missing+=(python3-numpy)
  "$PYTHON" -c 'import cv2' 2>/dev/null || missing+=(python3-opencv)
  "$PYTHON" -c 'import zxingcpp' 2>/dev/null || missing+=(python3-zxing-cpp)
  "$PYTHON" -c 'import serial' 2>/dev/null || missing+=(python3-serial)
  "$PYTHON" -c 'import ensurepip' 2>/dev/null || missing+=(python3-venv)
  if [ ${#missing[@]} -gt 0 ]; then
    _say "the headless install uses: sudo apt install $QRFIELD_OS_APT"
    _say "missing now: ${missing[*]}"
    answer=n
    if [ -t 0 ] && [ -t 2 ]; then
      read -r -p "qrfield: install them now with sudo apt? [y/N] " answer
    fi
    case "$answer" in
      y | Y | yes)
        sudo apt-get install -y $QRFIELD_OS_APT || exit 1
        ;;
      *)
        _say "not installed; run the apt command above, then this again"
        exit 1
        ;;
    esac
  fi
fi

# A venv without pip is remade: `python3 -m venv` leaves bin/python behind when it fails for want
# of ensurepip (Debian's python3-venv package), and every later run would then fail on pip.
if ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
  venv_args=()
  if $on_pi || $os_packages; then venv_args+=(--system-site-packages); fi
  if [ -f "$VENV/pyvenv.cfg" ]; then venv_args+=(--clear); fi
  _say "making the virtual environment $VENV (${venv_args[*]:-isolated})"
  if ! "$PYTHON" -m venv ${venv_args[@]+"${venv_args[@]}"} "$VENV"; then
    _say "could not make the virtual environment $VENV (see above); if it says ensurepip is not" \
      "available: sudo apt install python3-venv, then run this again"
    exit 1
  fi
  rm -f "$VENV/.qrfield-installed"
fi
VENV="$(cd -- "$VENV" && pwd -P)"  # absolute: test.sh moves to the repository after this

# What to install: a spec for pip and a word for the stamp.
if $os_packages; then
  kind="os-packages"
elif [ "$QRFIELD_INSTALL" = dev ]; then
  kind="gui,dev"
elif [ "${QRFIELD_WANT_APP:-0}" = 1 ] || _display_possible; then
  kind="gui"
else
  kind="core"
fi
stamp="$VENV/.qrfield-installed"
sum="$(cksum < "$QRFIELD_REPO/pyproject.toml")"
want="$sum $kind"
have="$(cat "$stamp" 2>/dev/null || true)"
# What is installed may be more than what is needed: the test tools' venv serves run.sh too.
case "$kind:$have" in
  "core:$sum gui" | "core:$sum gui,dev" | "gui:$sum gui,dev") want="$have" ;;
esac
if [ "$have" != "$want" ]; then
  pip=("$VENV/bin/python" -m pip --disable-pip-version-check)
  case "$kind" in
    os-packages)
      what="qrfield itself with --no-deps (numpy, OpenCV, zxing-cpp, pyserial from the OS's packages)"
      [ "$QRFIELD_INSTALL" = dev ] && what="$what, and pytest, pytest-timeout, hypothesis, ruff from PyPI"
      ;;
    core)
      what="qrfield with numpy, OpenCV, zxing-cpp and pyserial from PyPI (no display here, so not"
      what="$what the app's PySide6; QRFIELD_GUI=1 adds it)"
      ;;
    gui) what="qrfield with numpy, OpenCV, zxing-cpp, pyserial and, for the app, PySide6 and pyqtgraph from PyPI" ;;
    *) what="qrfield with the app's PySide6 and pyqtgraph and the test tools (pytest, hypothesis, ruff) from PyPI" ;;
  esac
  _say "installing into $VENV: $what. Once per change of pyproject.toml; the first time takes a few minutes."
  # pip's own output goes to stderr: stdout belongs to the command (./run.sh solve ... --json > out.json).
  "${pip[@]}" install --quiet --upgrade pip 1>&2 || _say "could not upgrade pip; going on with $("${pip[@]}" --version)"
  extra=()
  if $on_pi && ! $os_packages; then extra+=("numpy<2"); fi
  case "$kind" in
    os-packages)
      "${pip[@]}" install --no-deps -e "$QRFIELD_REPO" 1>&2 || exit 1
      if [ "$QRFIELD_INSTALL" = dev ]; then
        "${pip[@]}" install "pytest>=8" "pytest-timeout>=2.3" "hypothesis>=6" "ruff>=0.17,<0.18" 1>&2 || exit 1
      fi
      ;;
    core) "${pip[@]}" install -e "$QRFIELD_REPO" ${extra[@]+"${extra[@]}"} 1>&2 || exit 1 ;;
    *) "${pip[@]}" install -e "$QRFIELD_REPO[$kind]" ${extra[@]+"${extra[@]}"} 1>&2 || exit 1 ;;
  esac
  echo "$want" > "$stamp"
  _say "installed."
fi
