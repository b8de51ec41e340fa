#!/usr/bin/env bash
# Run a command in the workspace environment: the venv first on PATH (so
# 'python3' is the interpreter with rospy, casadi and pybullet) and the catkin
# devel space sourced.   Usage: scripts/env.sh COMMAND [ARGS...]
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -f "$ROOT/devel/setup.bash" ]; then
  echo "env: $ROOT/devel/setup.bash missing; run 'make build' first" >&2
  exit 1
fi
# sourced without arguments: setup.bash would hand ours (e.g. --help) to catkin's _setup_util.py
ARGS=("$@")
set --
# shellcheck disable=SC1091
source "$ROOT/devel/setup.bash"
export PATH="$ROOT/.venv/bin:$PATH"
export ROS_LOG_DIR="${ROS_LOG_DIR:-$ROOT/build/ros_log}"
export PYTHONDONTWRITEBYTECODE=1
# One arithmetic on every x86-64 machine with AVX2 and FMA (Intel since 2013, AMD since 2015), so that
# a sim seed gives the same run on the CI host as here: a run of coupled contacts is chaotic, and
# numpy's AVX-512 loops or OpenBLAS's per-CPU kernels change the last bits of the MPC's arithmetic
# (couple4_line seed 3 couples in 21.2 s with them on an AVX-512 host, 36.0 s pinned). Cost: about
# 5 % of a scenario trial's wall time. Set any of the three to override.
export NPY_DISABLE_CPU_FEATURES="${NPY_DISABLE_CPU_FEATURES-AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR}"
export OPENBLAS_CORETYPE="${OPENBLAS_CORETYPE-Haswell}"
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS-1}"
exec "${ARGS[@]}"
