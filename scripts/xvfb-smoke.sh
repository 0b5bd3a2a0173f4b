#!/usr/bin/env bash
# Smoke test of the real window: start a virtual X server (Xvfb), run `./run.sh --source virtual`
# on it (Qt's xcb platform, not offscreen), check that X maps a qrfield window, and that the
# screenshot the app saves before quitting is a real picture (not blank).
# Needs root or sudo for apt-get when Xvfb is missing. Not part of CI.
#   scripts/xvfb-smoke.sh [SCREENSHOT.png]        (default: /tmp/qrfield-xvfb-smoke.png)
# Environment: QRFIELD_VENV (run.sh's venv; default: run.sh's own), SMOKE_SECONDS (default 10).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-/tmp/qrfield-xvfb-smoke.png}"
SECONDS_UP="${SMOKE_SECONDS:-10}"
DISPLAY_NUM="${SMOKE_DISPLAY:-:97}"

need=()
command -v Xvfb >/dev/null || need+=(xvfb)
command -v xwininfo >/dev/null || need+=(x11-utils)
# Qt 6's xcb platform plugin needs these X client libraries.
for lib in libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxkbcommon-x11-0 \
           libxcb-cursor0 libxcb-shape0 libxcb-randr0 libxcb-xkb1 libegl1 libfontconfig1 libdbus-1-3; do
  dpkg -s "$lib" >/dev/null 2>&1 || need+=("$lib")
done
if [ ${#need[@]} -gt 0 ]; then
  echo "xvfb-smoke: installing ${need[*]}"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

# Let run.sh make its venv first (a first install takes minutes; the window test should not wait on it).
./run.sh --version

Xvfb "$DISPLAY_NUM" -screen 0 1400x900x24 -nolisten tcp >/tmp/qrfield-xvfb.log 2>&1 &
XVFB_PID=$!
CONFIG_DIR="$(mktemp -d)"
cleanup() { kill "$XVFB_PID" 2>/dev/null || true; rm -rf "$CONFIG_DIR"; }
trap cleanup EXIT
for _ in $(seq 50); do xwininfo -display "$DISPLAY_NUM" -root >/dev/null 2>&1 && break; sleep 0.1; done
xwininfo -display "$DISPLAY_NUM" -root >/dev/null 2>&1 || {
  echo "xvfb-smoke: FAIL: Xvfb did not start on $DISPLAY_NUM"; cat /tmp/qrfield-xvfb.log; exit 1; }

export DISPLAY="$DISPLAY_NUM"
unset QT_QPA_PLATFORM WAYLAND_DISPLAY
rm -f "$OUT"
./run.sh --source virtual --config-dir "$CONFIG_DIR" --quit-after "$SECONDS_UP" --screenshot "$OUT" \
  >/tmp/qrfield-xvfb-app.log 2>&1 &
APP_PID=$!
# While the app runs, X must know a mapped top-level window titled "qrfield ...".
found=""
for _ in $(seq $((SECONDS_UP * 10 + 600))); do
  if xwininfo -root -tree 2>/dev/null | grep -q '"qrfield.*bench"'; then
    found="$(xwininfo -root -tree | grep '"qrfield.*bench"' | head -1)"
    break
  fi
  kill -0 "$APP_PID" 2>/dev/null || break
  sleep 0.1
done
status=0
wait "$APP_PID" || status=$?
cat /tmp/qrfield-xvfb-app.log
if [ -z "$found" ]; then
  kill -0 "$XVFB_PID" 2>/dev/null || echo "xvfb-smoke: Xvfb had stopped: $(cat /tmp/qrfield-xvfb.log)"
  echo "xvfb-smoke: FAIL: no qrfield window appeared on $DISPLAY_NUM"; exit 1
fi
echo "xvfb-smoke: X window: $found"
if [ "$status" -ne 0 ]; then echo "xvfb-smoke: FAIL: the app exited with $status"; exit 1; fi
grep -q "platform xcb" /tmp/qrfield-xvfb-app.log || { echo "xvfb-smoke: FAIL: Qt did not use xcb"; exit 1; }
PY="${QRFIELD_VENV:-.venv}/bin/python"
"$PY" - "$OUT" <<'PYCHECK'
import sys
import cv2
image = cv2.imread(sys.argv[1])
if image is None:
    sys.exit(f"xvfb-smoke: FAIL: no screenshot at {sys.argv[1]}")
h, w = image.shape[:2]
std = float(image.std())
colours = len({tuple(p) for p in image[::7, ::7].reshape(-1, 3)})
print(f"xvfb-smoke: screenshot {sys.argv[1]}: {w}x{h}, grey-level std {std:.1f}, {colours} colours sampled")
if w < 400 or h < 300 or std < 20 or colours < 50:
    sys.exit("xvfb-smoke: FAIL: the screenshot looks blank")
PYCHECK
echo "xvfb-smoke: PASS"
