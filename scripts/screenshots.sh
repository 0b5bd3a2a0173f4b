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
status=0
work="$(mktemp -d)"
XVFB_PID=""
cleanup() { [ -n "$XVFB_PID" ] && kill "$XVFB_PID" 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
for size in "${SIZES[@]}"; do
  # Xvfb picks a free display itself (-displayfd) and writes its number once it is ready: the app
  # never talks to another X server that happens to use a fixed number.
  : > "$work/display"
  exec {fd}> "$work/display"
  Xvfb -displayfd "$fd" -screen 0 "${size}x24" -nolisten tcp >"$work/xvfb.log" 2>&1 &
  XVFB_PID=$!
  exec {fd}>&-
  for _ in $(seq 100); do [ -s "$work/display" ] && break; sleep 0.1; done
  [ -s "$work/display" ] || { echo "screenshots: Xvfb did not start: $(cat "$work/xvfb.log")"; exit 1; }
  display=":$(head -1 "$work/display")"
  more=""
  [ "$size" = "800x480" ] && more="--all"  # the smallest screen: every Setup page and the dialogs too
  DISPLAY="$display" "$PY" scripts/screenshots.py --size "$size" --out "$OUT" $more || status=1
  kill "$XVFB_PID" 2>/dev/null || true
  wait "$XVFB_PID" 2>/dev/null || true
  XVFB_PID=""
done
exit $status
