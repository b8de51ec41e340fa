#!/usr/bin/env bash
# 'make sim': run sim.launch headless with the default scenario (or the
# roslaunch arguments given), then print the scenario summary as the last
# thing on screen. Exits 0 only if every step of the scenario succeeded.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
summary="$ROOT/build/sim_summary.json"
rm -f "$summary"
"$ROOT/scripts/env.sh" roslaunch puzzlebot_bringup sim.launch summary_file:="$summary" "$@"
if [ ! -f "$summary" ]; then
  echo "sim: the scenario runner wrote no summary (see the log above)" >&2
  exit 1
fi
"$ROOT/.venv/bin/python" - "$summary" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(d["text"])
sys.exit(0 if d["passed"] else 1)
PY
