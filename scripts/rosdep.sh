#!/usr/bin/env bash
# rosdep on this workspace with its shipped source, without touching /etc/ros or the network:
# a private rosdep configuration in build/rosdep with two sources, this workspace's rosdep/puzzlebot.yaml
# and Debian's rules (/usr/share/python3-rosdep2/debian.yaml), an empty rosdistro index, and .venv first
# on PATH (the pip of rosdep's pip rules is the venv's).
#   scripts/rosdep.sh check      rosdep check --from-paths src --ignore-src   (after make setup: all satisfied)
#   scripts/rosdep.sh install    rosdep install --from-paths src --ignore-src -y (apt with sudo, pip into .venv)
#   scripts/rosdep.sh keys       the keys the packages declare, resolved
# Needs python3-rosdep2 (Debian; scripts/setup.sh installs it). README: "Set-up with rosdep".
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
what="${1:-check}"
shift || true
DEBIAN_RULES=/usr/share/python3-rosdep2/debian.yaml
command -v rosdep >/dev/null || { echo "rosdep.sh: rosdep not found (apt-get install python3-rosdep2)" >&2; exit 2; }
[ -f "$DEBIAN_RULES" ] || { echo "rosdep.sh: $DEBIAN_RULES missing (Debian's python3-rosdep2)" >&2; exit 2; }
HOME_DIR="$ROOT/build/rosdep"
mkdir -p "$HOME_DIR/sources.list.d"
printf 'yaml file://%s/rosdep/puzzlebot.yaml\n' "$ROOT" > "$HOME_DIR/sources.list.d/05-puzzlebot.list"
printf 'yaml file://%s debian\n' "$DEBIAN_RULES" > "$HOME_DIR/sources.list.d/10-debian.list"
export ROSDEP_SOURCE_PATH="$HOME_DIR/sources.list.d"
export ROSDISTRO_INDEX_URL="file://$ROOT/rosdep/index-v4.yaml"
export ROS_HOME="$HOME_DIR"
export ROS_PYTHON_VERSION=3
[ -x "$ROOT/.venv/bin/python" ] && export PATH="$ROOT/.venv/bin:$PATH"
rosdep update -q >/dev/null 2>&1 || { echo "rosdep.sh: rosdep update failed" >&2; rosdep update; exit 1; }
case "$what" in
  check) exec rosdep check --from-paths src --ignore-src "$@" ;;
  install) exec rosdep install --from-paths src --ignore-src -y --as-root pip:false "$@" ;;
  keys) rosdep keys --from-paths src --ignore-src | sort | xargs rosdep resolve "$@" ;;
  *) echo "usage: $0 [check|install|keys] [rosdep options]" >&2; exit 2 ;;
esac
