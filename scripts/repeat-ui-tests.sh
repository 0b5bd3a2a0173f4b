#!/usr/bin/env bash
# Run the UI tests (tests/ui) N times in a row (default 20), each run bounded by a ceiling, and
# print one line per run and a summary: the check that closing windows never hangs (issue 24).
# A run that hangs is killed at the ceiling and counted as HANG (pytest's faulthandler has
# already written every thread's stack to the run's log by then). Runs under `nice`; extra
# arguments go to pytest (e.g. -x, -k wheel). Logs: $QRFIELD_REPEAT_LOGS (default a temp folder).
#   scripts/repeat-ui-tests.sh [N] [pytest arguments...]
set -uo pipefail
runs=20
if [[ "${1:-}" =~ ^[0-9]+$ ]]; then
  runs="$1"
  shift
fi
QRFIELD_INSTALL=dev
source "$(dirname -- "${BASH_SOURCE[0]}")/venv.sh"
cd "$QRFIELD_REPO" || exit 1
logs="${QRFIELD_REPEAT_LOGS:-$(mktemp -d -t qrfield-ui-runs.XXXXXX)}"
mkdir -p "$logs"
#: One run's ceiling, s: the UI tests take 3-4 min on a loaded two-core machine.
ceiling="${QRFIELD_REPEAT_CEILING_S:-1200}"
export QT_QPA_PLATFORM=offscreen
echo "qrfield: $runs runs of tests/ui, logs in $logs, load: $(cut -d' ' -f1-3 /proc/loadavg)"
passed=0
for ((k = 1; k <= runs; k++)); do
  log="$logs/run-$k.log"
  start=$(date +%s)
  timeout -k 30 "$ceiling" nice "$VENV/bin/python" -m pytest tests/ui -q -p no:cacheprovider "$@" >"$log" 2>&1
  code=$?
  seconds=$(($(date +%s) - start))
  summary="$(grep -E '^[0-9]+ (passed|failed)|^=+ .*(passed|failed|error).* =+$' "$log" | tail -1 | tr -d '=')"
  case "$code" in
    0) verdict=ok passed=$((passed + 1)) ;;
    124 | 137) verdict=HANG ;;
    *) verdict=FAILED ;;
  esac
  printf 'run %2d: %-6s exit %3d, %4d s, %s\n' "$k" "$verdict" "$code" "$seconds" "${summary:-no summary}"
done
echo "qrfield: $passed of $runs runs passed, load: $(cut -d' ' -f1-3 /proc/loadavg)"
[ "$passed" -eq "$runs" ]
