#!/usr/bin/env bash
# The screenshot of a session report in docs/sessions.md: a guided experiment on the virtual bench
# from plan to report, without a screen, then the report drawn by headless Chromium.
#   scripts/report-screenshot.sh [OUT.png]        (default: assets/screenshots/report.png)
# Needs Debian's chromium (apt-get install -y --no-install-recommends chromium). About 1-2 minutes
# (36 rows). Not part of CI.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-assets/screenshots/report.png}"
BROWSER="$(command -v chromium || command -v chromium-browser || true)"
[ -n "$BROWSER" ] || { echo "report-screenshot: chromium is missing (see the comment at the top)"; exit 1; }
./run.sh --version >/dev/null  # make the venv first
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export QRFIELD_CONFIG_DIR="$work/config"
./run.sh plan --combos all --angles 10,30,50 --z-mm 300 --out "$work/plan.csv"
session="$(./run.sh session new "$work/sessions" --name thesis-grid --camera picam-v2@640x480 \
  --side-mm 50 --method numerical --operator bench --notes "12 combinations x 3 tilts, virtual bench")"
./run.sh session run-plan "$session" --plan "$work/plan.csv" --source virtual >/dev/null
# The prediction with corners rounded to whole pixels (the study's 'round' degradation).
./run.sh report "$session" --set degradation=round
"$BROWSER" --headless --no-sandbox --disable-gpu --disable-background-networking --no-first-run \
  --user-data-dir="$work/profile" --hide-scrollbars --window-size=1100,1900 \
  --screenshot="$work/report.png" "file://$session/report.html" 2>/dev/null
mkdir -p "$(dirname "$OUT")"
cp "$work/report.png" "$OUT"
echo "wrote $OUT"
