#!/usr/bin/env bash
# The 32-bit Raspberry Pi OS path of docs/install.md on any Debian 12 machine: the OS's packages
# (python3-numpy 1.24, python3-opencv 4.6, python3-zxing-cpp 1.4, python3-pyqtgraph 0.13.1,
# python3-serial 3.5), a venv with the system site-packages, qrfield with --no-deps; then the
# headless run, a solve over the real photos, and the non-GUI test suite on those versions.
# Needs root or sudo for apt-get when the packages are missing. Not part of CI (minutes).
#   scripts/check-os-packages.sh [VENV_DIR]     (default: /tmp/qrfield-os-venv)
set -euo pipefail
REPO="$(cd -- "$(dirname -- "${BASH_SOURCE[0]}")/.." && pwd -P)"
VENV="${1:-/tmp/qrfield-os-venv}"
SYSTEM_PYTHON=/usr/bin/python3
if ! "$SYSTEM_PYTHON" -c "import numpy, cv2, zxingcpp, serial" 2>/dev/null; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get install -y --no-install-recommends python3-numpy python3-opencv python3-zxing-cpp \
    python3-pyqtgraph python3-serial python3-venv
fi
"$SYSTEM_PYTHON" -c "import numpy, cv2, zxingcpp, serial; print('OS packages: numpy', numpy.__version__, '| OpenCV', cv2.__version__, '| pyserial', serial.__version__)"
cd "$(mktemp -d)"
echo "== run.sh's OS-packages path (what 32-bit ARM takes)"
QRFIELD_OS_PACKAGES=1 PYTHON="$SYSTEM_PYTHON" QRFIELD_VENV="$VENV" "$REPO/run.sh" run --headless --source virtual --frames 3
photos="$REPO/../shared/data/qr-photos"
if [ -d "$photos" ]; then
  echo "== solve over the real photos"
  "$VENV/bin/qrfield" solve "$photos/**/*.[jp][pn]g" --focal-px 600 --side-mm 50 --method ippe --json 2>/dev/null \
    | "$VENV/bin/python" -c "import json, sys; d = json.load(sys.stdin); print(len({e['image'] for e in d}), 'images,', sum(e['status'] == 'ok' for e in d), 'solved')" \
    || true  # solve exits 1 when some image has no converged pose
fi
echo "== the non-GUI tests on these versions"
"$VENV/bin/python" -m pip install --disable-pip-version-check --quiet "pytest>=8" "pytest-timeout>=2.3" "hypothesis>=6.100"
cd "$REPO"
"$VENV/bin/python" -m pytest -q --ignore=tests/ui -p no:cacheprovider || true
