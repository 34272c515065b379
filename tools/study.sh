#!/usr/bin/env bash
# Set up everything on a fresh machine, then run the paper's damping study end to end.
#   bash tools/study.sh [--out DIR] [study options...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh"
# shellcheck source=tools/env.sh
source "$ROOT/tools/env.sh"
cd "$ROOT"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( ($$ % 100) + 101 ))}"
exec python -m pentapod_damper.study "$@"
