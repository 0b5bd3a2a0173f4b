#!/usr/bin/env bash
# Start qrfield from anywhere: make or reuse the virtual environment, install the project, and run
# `qrfield "$@"` in the caller's current folder (relative paths are the caller's:
# `../qrfield/run.sh marker --out card.svg` writes ./card.svg). Without a display it says so and how
# to run headless; without a camera it uses the virtual bench. See docs/install.md.
set -euo pipefail
# The app itself is asked for (no subcommand, `gui`, or app options only): install its extra even
# where no display is seen from this shell.
case "${1:-}" in
  "" | gui) QRFIELD_WANT_APP=1 ;;
  -h | --help | --version) QRFIELD_WANT_APP=0 ;;
  -*) QRFIELD_WANT_APP=1 ;;
  *) QRFIELD_WANT_APP=0 ;;
esac
QRFIELD_INSTALL=app
source "$(dirname -- "${BASH_SOURCE[0]}")/scripts/venv.sh"
exec "$VENV/bin/qrfield" "$@"
