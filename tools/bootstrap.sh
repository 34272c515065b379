#!/usr/bin/env bash
# Create (or update) the virtual environment with every dependency and install the package.
# Idempotent: a second run only reinstalls the package itself.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${PENTAPOD_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    echo "[bootstrap] creating virtual environment $VENV"
    "$PY" -m venv "$VENV"
fi
STAMP="$VENV/.requirements.sha256"
WANT="$(cat "$ROOT/requirements.txt" "$ROOT/requirements-dev.txt" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
    echo "[bootstrap] installing dependencies (ROS 2 Jazzy wheels, numpy/scipy/control, mcap, ...)"
    "$VENV/bin/python" -m pip install --quiet --upgrade pip
    "$VENV/bin/python" -m pip install --quiet -r "$ROOT/requirements-dev.txt" 2>&1 | { grep -v "is ignored: it is neither" || true; }
    echo "$WANT" > "$STAMP"
fi
echo "[bootstrap] installing pentapod_testbed into $VENV"
# Not editable: data_files (ament index marker, config, launch, lib/<pkg> launchers) must land
# in the prefix for ros2 run / ros2 launch.
"$VENV/bin/python" -m pip install --quiet --no-deps --force-reinstall "$ROOT" 2>&1 | { grep -v "is ignored: it is neither" || true; }
