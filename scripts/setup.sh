#!/usr/bin/env bash
# One-time (idempotent) setup of the PuzzleBot workspace on Debian 12:
#   1. Debian's ROS 1 packages with apt (skipped when all are installed),
#   2. .venv: a venv on /usr/bin/python3 (sees Debian's rospy) with the
#      pinned PyPI packages of requirements.txt (skipped when unchanged),
#   3. catkin_make with that venv's interpreter (incremental).
# Usage: scripts/setup.sh [deps|build|all]   (default: all)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
what="${1:-all}"

APT_PACKAGES=(
  catkin python3-catkin-pkg ros-message-generation ros-message-runtime librostest-dev
  python3-rospy python3-roslaunch python3-rostest python3-rosbag python3-rosnode python3-rostopic
  python3-rosparam python3-rosservice python3-rosmsg python3-genpy python3-gencpp python3-genmsg python3-rosgraph
  python3-rospkg python3-yaml python3-dateutil
  python3-tf2-ros python3-geometry-msgs python3-std-msgs python3-sensor-msgs python3-visualization-msgs
  python3-diagnostic-msgs python3-rosgraph-msgs python3-tf2-msgs ros-geometry-msgs ros-std-msgs ros-visualization-msgs
  ros-diagnostic-msgs libstd-msgs-dev libgeometry-msgs-dev libdiagnostic-msgs-dev libtf2-ros-dev
  rosout rosbash rospack-tools rviz xvfb x11-apps python3-venv python3-dev
  # the behaviour action (python3-actionlib; the -msgs packages build it), live tuning, the robot model
  python3-actionlib libactionlib-dev python3-actionlib-msgs ros-actionlib-msgs libactionlib-msgs-dev
  python3-dynamic-reconfigure ros-robot-state-publisher
  # diagnostics: the aggregator (its plugins are in the -dev package) and the printer (health)
  libdiagnostic-aggregator-tools libdiagnostic-aggregator-dev rosdiagnostic
  # tf tools (view_frames, tf_monitor, tf_echo) and rosdep (scripts/rosdep.sh, README "Set-up with rosdep")
  tf2-tools tf-tools python3-tf python3-rosdep2
)

log() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

install_apt() {
  local missing=()
  for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    log "Debian packages: all ${#APT_PACKAGES[@]} installed"
    return
  fi
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  log "Debian packages: installing ${#missing[@]} (${missing[*]:0:6} ...)"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${APT_PACKAGES[@]}" >/dev/null
}

install_venv() {
  local stamp="$VENV/.requirements.sha256"
  local want
  want="$(sha256sum requirements.txt | cut -d' ' -f1)"
  if [ -x "$VENV/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    log "Python environment: .venv up to date"
    return
  fi
  if [ ! -x "$VENV/bin/python" ]; then
    log "Python environment: creating .venv on /usr/bin/python3"
    /usr/bin/python3 -m venv --system-site-packages "$VENV"
  fi
  log "Python environment: installing requirements.txt"
  "$VENV/bin/pip" install -q --disable-pip-version-check -r requirements.txt
  "$VENV/bin/python" -c "import casadi, pybullet, rospy, numpy" 2>/dev/null \
    || { echo "setup: .venv cannot import casadi, pybullet, rospy and numpy" >&2; exit 1; }
  echo "$want" > "$stamp"
}

build() {
  log "catkin_make (PYTHON_EXECUTABLE=$VENV/bin/python)"
  # catkin's setup files reference unset variables: no 'set -u' while sourcing.
  mkdir -p build
  set +u
  catkin_make -DPYTHON_EXECUTABLE="$VENV/bin/python" -DCATKIN_ENABLE_TESTING=ON \
    -DCMAKE_BUILD_TYPE=Release > build/catkin_make.log 2>&1 \
    || { tail -40 build/catkin_make.log >&2; echo "setup: catkin_make failed (build/catkin_make.log)" >&2; exit 1; }
  set -u
}

case "$what" in
  deps) install_apt; install_venv ;;
  build) build ;;
  all) install_apt; install_venv; build ;;
  *) echo "usage: $0 [deps|build|all]" >&2; exit 2 ;;
esac
