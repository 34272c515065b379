#!/usr/bin/env bash
# Set up everything on a fresh machine, then run the whole test suite.
#   bash tools/test.sh [pytest args...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh"
# shellcheck source=tools/env.sh
source "$ROOT/tools/env.sh"
cd "$ROOT"
# a per-run DDS domain keeps concurrent runs on this host apart
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( ($$ % 100) + 1 ))}"
exec python -m pytest -q -p no:cacheprovider "$@"
