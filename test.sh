#!/usr/bin/env bash
# Run the whole test suite: make or reuse a venv, install qrfield with its dev tools, run ruff
# (lint and format check) and pytest with Qt offscreen. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")"
source scripts/venv.sh
echo "== ruff"
"$VENV/bin/ruff" check .
"$VENV/bin/ruff" format --check .
echo "== pytest"
export QT_QPA_PLATFORM=offscreen
exec "$VENV/bin/python" -m pytest "$@"
