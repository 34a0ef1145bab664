#!/usr/bin/env bash
# `make bench`: the rerunnable benchmarks in bench/ (after the set-up), each printing a
# table and writing bench/results/*.json:
#   bench/bench_planner.py  plan time per object, vs particles / iterations / mesh triangles
#   bench/bench_decode.py   object preparation and particle decoding
#   bench/bench_node.py     ROS service overhead and a memory soak of the node
#   bench/bench_scene.py    plan time with a table and with a box obstacle vs free space
#   bench/bench_candidates.py  5 candidates vs one grasp, verified candidates per second
#   bench/bench_simulation.py  ms per simulated grasp (MuJoCo)
#   bench/bench_load.py     a 30-request burst and 200 sequential requests, node RSS
#   bench/bench_node_workers.py  node throughput, 4 callers, workers 1 vs 2
#   bench/bench_batch.py    batch objects/min: 1 vs 2 local workers, Ray vs the pool
#   bench/bench_node_database.py  round trip of a request answered from the database
# Longer ones, run by hand: bench/held_rate.py (held rate in simulation, issue 13),
# bench/scene_acceptance.py (every real mesh on a table, python-fcl check).
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
for script in bench/bench_planner.py bench/bench_decode.py bench/bench_node.py bench/bench_scene.py \
    bench/bench_candidates.py bench/bench_simulation.py bench/bench_load.py bench/bench_node_workers.py \
    bench/bench_batch.py bench/bench_node_database.py; do
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
