#!/usr/bin/env bash
# The whole test suite: pytest on the ROS-free cores (no roscore), then every
# rostest registered with add_rostest (each brings up its own master on a free
# port). Exits non-zero if anything failed. JUnit XML lands in build/test_results.
# Usage: scripts/run_tests.sh [unit|ros|all]   (default: all)
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
what="${1:-all}"
results="$ROOT/build/test_results"
status=0
t0=$(date +%s)

if [ "$what" = all ] || [ "$what" = unit ]; then
  echo "== pytest (ROS-free cores)"
  mkdir -p "$results/pytest"
  scripts/env.sh python -m pytest -q --junitxml="$results/pytest/pytest.xml" || status=1
fi

if [ "$what" = all ] || [ "$what" = ros ]; then
  echo "== rostest (node integration)"
  # catkin's run_tests target runs every add_rostest; results as JUnit XML.
  rm -rf "$results"/puzzlebot_*
  # ROS_TEST_RESULTS_DIR: tests that write files (rviz screenshot, recorded bag) put them next to the XML;
  # through env.sh like every other run, so the rostests get its pinned arithmetic (the same run per sim
  # seed on every host, docs/bringup.md)
  ROS_TEST_RESULTS_DIR="$results" scripts/env.sh catkin_make run_tests -DPYTHON_EXECUTABLE="$ROOT/.venv/bin/python" > build/run_tests.log 2>&1 || true
  grep -E "^\[Testcase|^\[.*\]\[(passed|FAILURE|ERROR)\]|RESULT:" build/run_tests.log || true
  scripts/env.sh catkin_test_results "$results" || status=1
fi

if [ $status -ne 0 ]; then
  echo "== what the failed tests said"
  scripts/env.sh python scripts/test_failures.py "$results" || true
fi
echo "== test suite $( [ $status -eq 0 ] && echo PASSED || echo FAILED ) in $(( $(date +%s) - t0 )) s"
exit $status
