#!/usr/bin/env bash
# Run the whole test suite from anywhere: make or reuse the venv, install qrfield with its app and
# dev tools, run ruff (lint and format check) and pytest with Qt offscreen. Extra arguments go to
# pytest; file and folder arguments are the caller's (`../qrfield/test.sh ../qrfield/tests/test_x.py`
# and, in the repository, `./test.sh tests/test_x.py` both work); the suite runs from the repository.
set -euo pipefail
QRFIELD_INSTALL=dev
source "$(dirname -- "${BASH_SOURCE[0]}")/scripts/venv.sh"
# Paths the caller named become absolute before the suite moves to the repository (pytest reads its
# configuration and conftest.py from there). The values of pytest's options that take one are left
# as they are.
args=()
value_next=false
for arg in "$@"; do
  if $value_next; then
    args+=("$arg")
    value_next=false
    continue
  fi
  case "$arg" in
    -k | -m | -p | -o | -c | -W | -r | -n | --timeout | --maxfail | --durations | --log-level | --tb)
      args+=("$arg")
      value_next=true
      ;;
    -*) args+=("$arg") ;;
    *)
      target="${arg%%::*}"
      if [ -e "$target" ]; then
        args+=("$(cd -- "$(dirname -- "$target")" && pwd -P)/$(basename -- "$target")${arg#"$target"}")
      else
        args+=("$arg")
      fi
      ;;
  esac
done
cd "$QRFIELD_REPO"
echo "== ruff"
"$VENV/bin/ruff" check .
"$VENV/bin/ruff" format --check .
echo "== pytest"
export QT_QPA_PLATFORM=offscreen
exec "$VENV/bin/python" -m pytest ${args[@]+"${args[@]}"}
