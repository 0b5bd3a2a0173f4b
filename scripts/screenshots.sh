#!/usr/bin/env bash
# Screenshots of every tab of the bench app at 800x480 (Raspberry Pi Touch Display), 1024x600 and
# 1300x820, each on an Xvfb screen of exactly that size (scripts/screenshots.py drives the app);
# at 800x480 also every Setup page and the New session and calibration dialogs.
#   scripts/screenshots.sh [OUT_DIR] [SIZE ...]      (default: assets/screenshots, the three sizes)
# Needs Xvfb and ImageMagick: apt-get install -y --no-install-recommends xvfb imagemagick
#   libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxkbcommon-x11-0 libxcb-cursor0
# (scripts/xvfb-smoke.sh installs the same X libraries). Not part of CI.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-assets/screenshots}"
shift || true
SIZES=("$@")
[ ${#SIZES[@]} -gt 0 ] || SIZES=(800x480 1024x600 1300x820)
command -v Xvfb >/dev/null || { echo "screenshots: Xvfb is missing (see the comment at the top)"; exit 1; }
./run.sh --version >/dev/null  # make the venv first
PY="${QRFIELD_VENV:-.venv}/bin/python"
DISPLAY_NUM="${SHOT_DISPLAY:-:96}"
status=0
for size in "${SIZES[@]}"; do
  Xvfb "$DISPLAY_NUM" -screen 0 "${size}x24" -nolisten tcp >/tmp/qrfield-screenshots-xvfb.log 2>&1 &
  XVFB_PID=$!
  trap 'kill "$XVFB_PID" 2>/dev/null || true' EXIT
  for _ in $(seq 50); do xdpyinfo -display "$DISPLAY_NUM" >/dev/null 2>&1 && break; sleep 0.1; done
  more=""
  [ "$size" = "800x480" ] && more="--all"  # the smallest screen: every Setup page and the dialogs too
  DISPLAY="$DISPLAY_NUM" "$PY" scripts/screenshots.py --size "$size" --out "$OUT" $more || status=1
  kill "$XVFB_PID" 2>/dev/null || true
  wait "$XVFB_PID" 2>/dev/null || true
done
exit $status
