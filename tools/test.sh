#!/usr/bin/env bash
# Set up everything on a fresh machine, then run the whole test suite.
#   bash tools/test.sh [pytest args...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/tools/bootstrap.sh"
# shellcheck source=tools/env.sh
source "$ROOT/tools/env.sh"
cd "$ROOT"
# conftest.py reserves a free ROS domain for the pytest session (unless ROS_DOMAIN_ID is set)
# and keeps discovery on this host: concurrent runs on this host never share a domain
# the ecosystem's lint rules (ruff.toml: ament's flake8/pep257 settings) and the core's types
ruff check --no-cache -q .
mypy --no-incremental --cache-dir=/dev/null
# on two parallel workers by default (PENTAPOD_TEST_WORKERS: a number, auto, or 0 for one
# process), each on a ROS domain of its own: 20 min instead of 35 on this 2-core machine. Under
# that load a recorder once missed a source's forces for a whole short run: DDS discovery took
# an announcement period, now 0.5 s (config/dds/loopback.xml), and the recorder subscribes to
# the force topics the plant announces (test_discovery_delay, test_recorder_announced). The
# slowest tests are listed at the end: CI should stay under 30 minutes
exec python -m pytest -q -p no:cacheprovider -n "${PENTAPOD_TEST_WORKERS:-2}" \
    --dist worksteal --durations=30 "$@"
