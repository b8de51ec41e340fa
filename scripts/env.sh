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
exec "${ARGS[@]}"
