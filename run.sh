#!/usr/bin/env bash
# Start qrfield: make or reuse a virtual environment, install the project, run `qrfield "$@"`.
# Without a display it says so and how to run headless; without a camera it uses the virtual bench.
# The command runs in the caller's folder, so that relative paths (e.g. --out) are the caller's.
set -euo pipefail
caller="$PWD"
cd "$(dirname "$0")"
source scripts/venv.sh
qrfield="$(cd "$VENV/bin" && pwd)/qrfield"
cd "$caller"
exec "$qrfield" "$@"
