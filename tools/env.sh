# Source this file to work in the project's virtual environment (bash).
# Sets what the ROS 2 wheels and the tests need; safe to source twice.
_PT_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export PENTAPOD_ROOT="$_PT_ROOT"
export VIRTUAL_ENV="${PENTAPOD_VENV:-$_PT_ROOT/.venv}"
export PATH="$VIRTUAL_ENV/bin:$PATH"
# ament_index_python finds packages (ours and the message packages) only with this set
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# small dense linear algebra: threaded BLAS is many times slower on 2 cores
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
# DDS on the loopback interface only, unless you chose a discovery range, static peers or a
# DDS profile (docs/nodes.md, "Isolation and networks"): the package's Fast DDS profile and
# ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT, as the runner and every node set them
if _pt_exports="$(cd "$PENTAPOD_ROOT" && python -m pentapod_sim.scenario.network 2>/dev/null)"; then
    eval "$_pt_exports"
fi
unset _pt_exports
export MPLBACKEND="${MPLBACKEND:-Agg}"
unset _PT_ROOT
