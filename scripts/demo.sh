#!/usr/bin/env bash
# THE demo of grasp_apso (`make demo`): plan a grasp through the real ROS 2 node.
#   1. set-up if needed (scripts/setup.sh; `make demo` always runs it first)
#   2. start the node (planner_node) in the background, in a DDS domain of its own
#   3. wait for its service, call it for a built-in object resting on a table (one support
#      plane under its lowest point; --no-table for free space) with max_grasps 5, print the
#      best grasp, the ranked candidates (quality, epsilon, wrist, approach) and how many
#      progress messages arrived on /grasp_apso/progress (grasp_apso/ros/demo_client.py)
#   4. stop the node cleanly (SIGINT, wait), also when something fails
#
# Usage: bash scripts/demo.sh [sphere|cube|barrel|fish] [--hand FILE [--hand-config FILE]]
#                             [demo_client options...]
#        e.g. bash scripts/demo.sh cube --algorithm pso --seed 3 --grasps 3 --no-table
#             bash scripts/demo.sh --hand my_hand.urdf --mesh grasp_apso/data/meshes/mug.stl
#   --hand / --hand-config go to the node (parameters hand_description / hand_config: any
#   URDF or MJCF hand, loaded and checked at start-up); the rest to the demo client.
# Environment:
#   DEMO_ROS_DOMAIN_ID=N   DDS domain for the node and the client (default: one from the PID)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${GRASP_APSO_VENV:-$ROOT/.venv}"
PY="$VENV/bin/python"

say() { printf '[demo] %s\n' "$*"; }

if [ ! -x "$PY" ] || ! "$PY" -c 'import rclpy, grasp_apso_interfaces' >/dev/null 2>&1; then
  say "the venv is not set up yet: running scripts/setup.sh"
  bash "$ROOT/scripts/setup.sh"
fi

OBJECT="fish"
if [ "$#" -gt 0 ] && [ "${1#-}" = "$1" ]; then OBJECT="$1"; shift; fi
NODE_PARAMS=()
CLIENT_ARGS=()
WAIT=30
while [ "$#" -gt 0 ]; do
  case "$1" in
    --hand|--hand-config)
      [ "$#" -ge 2 ] || { say "error: $1 needs a file"; exit 2; }
      [ -f "$2" ] || { say "error: $1: no such file: $2"; exit 2; }
      key=hand_description; [ "$1" = "--hand-config" ] && key=hand_config
      NODE_PARAMS+=(-p "$key:=$(cd "$(dirname "$2")" && pwd)/$(basename "$2")")
      WAIT=300  # a hand new to this machine: its sphere cover is built once before "ready"
      shift 2 ;;
    *) CLIENT_ARGS+=("$1"); shift ;;
  esac
done

# Isolation: a DDS domain of this demo only (102..201; the tests use 1..101), discovery
# on this machine only, ROS log files in a temporary folder. The working tree's sources.
export ROS_DOMAIN_ID="${DEMO_ROS_DOMAIN_ID:-$(( ($$ % 100) + 102 ))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_LOCALHOST_ONLY ROS_STATIC_PEERS
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
RUN_DIR="$(mktemp -d "${TMPDIR:-/tmp}/grasp_apso_demo.XXXXXX")"
export ROS_LOG_DIR="$RUN_DIR/ros_log"
NODE_LOG="$RUN_DIR/node.log"
NODE_PID=""

stop_node() {
  local status=0
  if [ -n "$NODE_PID" ] && kill -0 "$NODE_PID" 2>/dev/null; then
    say "stopping the node (SIGINT to pid $NODE_PID)"
    kill -INT "$NODE_PID" 2>/dev/null || true
    for _ in $(seq 100); do
      kill -0 "$NODE_PID" 2>/dev/null || break
      sleep 0.1
    done
    if kill -0 "$NODE_PID" 2>/dev/null; then
      say "the node did not stop within 10 s: SIGKILL"
      kill -KILL "$NODE_PID" 2>/dev/null || true
    fi
    wait "$NODE_PID" 2>/dev/null || status=$?
    say "node stopped (exit status $status)"
  fi
  NODE_PID=""
  return 0
}

cleanup() {
  local status=$?
  stop_node
  if [ "$status" -ne 0 ] && [ -s "$NODE_LOG" ]; then
    say "node log ($NODE_LOG):"
    sed 's/^/    /' "$NODE_LOG" | tail -n 30
    say "logs kept in $RUN_DIR"
  else
    rm -rf "$RUN_DIR"
  fi
  exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

say "starting the node: planner_node (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, log: $NODE_LOG)"
"$PY" -m grasp_apso.ros.node --ros-args --params-file "$ROOT/config/grasp_apso.yaml" \
    ${NODE_PARAMS[@]+"${NODE_PARAMS[@]}"} >"$NODE_LOG" 2>&1 &
NODE_PID=$!

client_status=0
"$PY" -m grasp_apso.ros.demo_client "$OBJECT" --wait "$WAIT" ${CLIENT_ARGS[@]+"${CLIENT_ARGS[@]}"} || client_status=$?
if ! kill -0 "$NODE_PID" 2>/dev/null; then
  say "error: the node is not running any more"
  exit 1
fi
stop_node
case "$client_status" in
  0) say "done: the node planned valid grasps" ;;
  2) say "the node answered, but did not find a valid grasp (see the message above)" ;;
  *) say "error: the demo client failed (status $client_status)" ;;
esac
exit "$client_status"
