#!/usr/bin/env bash
# Start qrfield: make or reuse a virtual environment, install the project, run `qrfield "$@"`.
# Without a display it says so and how to run headless; without a camera it uses the virtual bench.
set -euo pipefail
cd "$(dirname "$0")"
source scripts/venv.sh
exec "$VENV/bin/qrfield" "$@"
