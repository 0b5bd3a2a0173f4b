#!/usr/bin/env bash
# Must show of docs/install.md: in a fresh venv, `pip install .` (no extras) then
#   qrfield run --headless --source virtual --frames 3
# works with PySide6 absent, and `qrfield gui` says which extra to install. Not part of CI (it
# downloads and installs numpy, OpenCV and zxing-cpp into a new venv: a minute or more).
#   scripts/check-headless-install.sh [VENV_DIR]   (default: a temporary folder, removed after)
set -euo pipefail
REPO="$(cd -- "$(dirname -- "${BASH_SOURCE[0]}")/.." && pwd -P)"
PYTHON="${PYTHON:-python3}"
if [ $# -ge 1 ]; then
  VENV="$1"
else
  VENV="$(mktemp -d)/venv"
  trap 'rm -rf "$(dirname "$VENV")"' EXIT
fi
echo "== fresh venv $VENV"
"$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install --disable-pip-version-check --quiet "$REPO"
echo "== installed: $("$VENV/bin/python" -m pip list --disable-pip-version-check 2>/dev/null | grep -iE '^(numpy|opencv|zxing|pyserial|pyside6|pyqtgraph)' | tr -s ' ' | tr '\n' ';')"
if "$VENV/bin/python" -c "import PySide6" 2>/dev/null; then
  echo "FAIL: PySide6 was installed by pip install . (it belongs to the gui extra)" >&2
  exit 1
fi
if "$VENV/bin/python" -c "import pyqtgraph" 2>/dev/null; then
  echo "FAIL: pyqtgraph was installed by pip install . (it belongs to the gui extra)" >&2
  exit 1
fi
cd "$(dirname "$VENV")"  # away from the checkout: the installed package, not the source tree
echo "== qrfield run --headless --source virtual --frames 3"
"$VENV/bin/qrfield" run --headless --source virtual --frames 3 --json-lines > frames.jsonl
lines=$(wc -l < frames.jsonl)
ok=$(grep -c '"status": "OK"' frames.jsonl || true)
echo "$lines frames, $ok with status OK"
[ "$lines" = 3 ] && [ "$ok" = 3 ] || { echo "FAIL: expected 3 OK frames" >&2; exit 1; }
echo "== qrfield gui without the extra"
set +e
QT_QPA_PLATFORM=offscreen "$VENV/bin/qrfield" gui 2> gui.err
code=$?
set -e
cat gui.err
if [ "$code" != 3 ] || ! grep -q "qrfield\[gui\]" gui.err; then
  echo "FAIL: qrfield gui should exit 3 naming the gui extra (got $code)" >&2
  exit 1
fi
echo "PASS: the core installs and runs headless without Qt; the app names its extra"
