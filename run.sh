#!/usr/bin/env bash
# Start qrfield: make or reuse a virtual environment, install the project, run `qrfield "$@"`.
# On Raspberry Pi OS the venv sees the system's site-packages, so the OS's picamera2 is used.
set -euo pipefail
cd "$(dirname "$0")"
VENV="${QRFIELD_VENV:-.venv}"
PYTHON="${PYTHON:-python3}"

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "qrfield needs Python 3.11 or newer; found: $("$PYTHON" --version 2>&1)" >&2
  exit 1
fi
is_raspberry_pi() {
  [ -f /etc/rpi-issue ] || grep -qs "Raspberry Pi" /proc/device-tree/model
}
if [ ! -x "$VENV/bin/python" ]; then
  if is_raspberry_pi; then
    "$PYTHON" -m venv --system-site-packages "$VENV"
  else
    "$PYTHON" -m venv "$VENV"
  fi
fi
# Reinstall only when the project's metadata changed (keeps start-up fast).
stamp="$VENV/.qrfield-installed"
want="$(cat pyproject.toml | cksum)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  "$VENV/bin/python" -m pip install --quiet -e ".[dev]"
  echo "$want" > "$stamp"
fi
exec "$VENV/bin/qrfield" "$@"
