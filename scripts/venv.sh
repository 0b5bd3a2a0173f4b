# Sourced by run.sh and test.sh: make or reuse the venv "$VENV" and install qrfield with its dev
# tools into it, again only when pyproject.toml changed. On Raspberry Pi OS the venv sees the
# system's site-packages, so that the OS's picamera2 (apt: python3-picamera2) is importable.
VENV="${QRFIELD_VENV:-.venv}"
PYTHON="${PYTHON:-python3}"

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "qrfield needs Python 3.11 or newer; found: $("$PYTHON" --version 2>&1)" >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
  if [ -f /etc/rpi-issue ] || grep -qs "Raspberry Pi" /proc/device-tree/model; then
    "$PYTHON" -m venv --system-site-packages "$VENV"
  else
    "$PYTHON" -m venv "$VENV"
  fi
fi
stamp="$VENV/.qrfield-installed"
want="$(cksum < pyproject.toml)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "installing qrfield into $VENV (once per change of pyproject.toml) ..." >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  "$VENV/bin/python" -m pip install --quiet -e ".[dev]"
  echo "$want" > "$stamp"
fi
