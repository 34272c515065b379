#!/usr/bin/env bash
# Set up everything on a fresh machine, then run the paper's damping study end to end.
#   bash tools/study.sh [--out DIR] [study options...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh"
# shellcheck source=tools/env.sh
source "$ROOT/tools/env.sh"
cd "$ROOT"
# each run of the study reserves a free ROS domain with localhost discovery for its nodes
# (pentapod_sim/scenario/domain.py) unless ROS_DOMAIN_ID is set
exec python -m pentapod_damper.study "$@"
