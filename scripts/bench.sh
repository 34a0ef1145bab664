#!/usr/bin/env bash
# `make bench`: the rerunnable benchmarks in bench/ (after the set-up), each printing a
# table and writing bench/results/*.json:
#   bench/bench_planner.py  plan time per object, vs particles / iterations / mesh triangles
#   bench/bench_decode.py   object preparation and particle decoding
#   bench/bench_node.py     ROS service overhead and a memory soak of the node
# Scripts that are not there yet are skipped. Extra arguments go to bench_planner.py.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${GRASP_APSO_VENV:-$ROOT/.venv}"
export MPLBACKEND=Agg
# The node benchmark: the venv is the ament prefix; discovery on this machine only.
export AMENT_PREFIX_PATH="$VENV"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"

status=0
for script in bench/bench_planner.py bench/bench_decode.py bench/bench_node.py; do
  if [ ! -f "$script" ]; then
    echo "[bench] $script: not there, skipped"
    continue
  fi
  echo "[bench] $script"
  if [ "$script" = bench/bench_planner.py ]; then
    "$VENV/bin/python" "$script" "$@" || status=$?
  else
    "$VENV/bin/python" "$script" || status=$?
  fi
done
exit "$status"
