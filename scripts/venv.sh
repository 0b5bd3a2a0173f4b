# Sourced by run.sh and test.sh: make or reuse the venv "$VENV" and install qrfield with its dev
# tools into it, again only when pyproject.toml changed. On Raspberry Pi OS the venv sees the
# system's site-packages, so that the OS's picamera2 (apt: python3-picamera2) is importable, and
# numpy stays 1.x there: Bookworm's picamera2 (its simplejpeg) is built for numpy 1.x and fails to
# import under numpy 2. pip then picks opencv-python-headless 4.11 (4.12 and later need numpy 2).
VENV="${QRFIELD_VENV:-.venv}"
PYTHON="${PYTHON:-python3}"

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "qrfield needs Python 3.11 or newer; found: $("$PYTHON" --version 2>&1)" >&2
  exit 1
fi
on_pi=false
if [ -f /etc/rpi-issue ] || grep -qs "Raspberry Pi" /proc/device-tree/model; then
  on_pi=true
fi
# A venv without pip is remade: `python3 -m venv` leaves bin/python behind when it fails for want
# of ensurepip (Debian's python3-venv package), and every later run would then fail on pip.
if ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
  venv_args=()
  if $on_pi; then venv_args+=(--system-site-packages); fi
  if [ -f "$VENV/pyvenv.cfg" ]; then venv_args+=(--clear); fi
  if ! "$PYTHON" -m venv ${venv_args[@]+"${venv_args[@]}"} "$VENV"; then
    echo "could not make the virtual environment $VENV (see above); if it says ensurepip is not" \
      "available: sudo apt install python3-venv, then run this again" >&2
    exit 1
  fi
  rm -f "$VENV/.qrfield-installed"
fi
stamp="$VENV/.qrfield-installed"
want="$(cksum < pyproject.toml)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "installing qrfield into $VENV (once per change of pyproject.toml) ..." >&2
  extra=()
  if $on_pi; then extra+=("numpy<2"); fi
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  "$VENV/bin/python" -m pip install --quiet -e ".[dev]" ${extra[@]+"${extra[@]}"}
  echo "$want" > "$stamp"
fi
