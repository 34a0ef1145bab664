#!/usr/bin/env bash
# THE test command of grasp_apso (README, `make test` and .ci/run all use it):
# set-up (quick when already done), then the whole pytest suite in test/ against the
# working tree, with an isolated ROS 2 environment for the node tests.
# Extra arguments go to pytest, e.g.  bash scripts/test.sh -k interfaces -x
# or  bash scripts/test.sh test/test_interfaces.py  (no arguments: testpaths = test).
#
# Environment:
#   PYTEST_TIMEOUT=SECONDS     time limit per test (default 300)
#   TEST_ROS_DOMAIN_ID=N       use this ROS_DOMAIN_ID instead of a per-run one
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${GRASP_APSO_VENV:-$ROOT/.venv}"

bash "$ROOT/scripts/setup.sh"

# Isolation of the ROS 2 tests: a DDS domain of this run only (1..101, from the PID),
# discovery on this machine only, log files in a temporary folder, Fast DDS.
export ROS_DOMAIN_ID="${TEST_ROS_DOMAIN_ID:-$(( ($$ % 101) + 1 ))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_LOCALHOST_ONLY ROS_STATIC_PEERS
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
ROS_LOG_DIR="$(mktemp -d "${TMPDIR:-/tmp}/grasp_apso_test_logs.XXXXXX")"
export ROS_LOG_DIR
# The venv is the ament prefix (ament_index_python lookups); nothing else from a sourced ROS.
export AMENT_PREFIX_PATH="$VENV"
unset PYTHONPATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH
# Headless plots.
export MPLBACKEND=Agg

echo "[test] pytest (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, ROS_LOG_DIR=$ROS_LOG_DIR, timeout ${PYTEST_TIMEOUT:-300} s per test)"
status=0
"$VENV/bin/python" -m pytest --timeout="${PYTEST_TIMEOUT:-300}" "$@" || status=$?

if [ "$status" -eq 0 ]; then
  rm -rf "$ROS_LOG_DIR"
else
  echo "[test] pytest exit status $status; ROS logs kept in $ROS_LOG_DIR"
fi
exit "$status"
