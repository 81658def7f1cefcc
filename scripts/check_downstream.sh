#!/bin/bash
# A package of someone else's, the catkin way: builds test/downstream_pkg (find_package(catkin
# COMPONENTS mild_lcd), mild_lcd's public headers, exported libraries and messages) against the devel
# space in $BUILD_DIR and runs its program; then the two examples of consuming LoopClosure in docs/interface.md
# (the package's C++ loop_closure_listener and scripts/loop_closure_listener.py), each on a private
# master, must print the accepted loop of a LoopClosure published to them, and docs/interface.md must show
# both files as they are. Writes the verdict as JUnit results that scripts/test.sh counts. Needs a
# built $BUILD_DIR (scripts/test.sh runs it after the build).
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RESULTS="$BUILD_DIR/test_results/mild_lcd"
OUT="$BUILD_DIR/downstream"
PKG="$REPO/test/downstream_pkg"
mkdir -p "$RESULTS"
rm -rf "$OUT"

junit() {  # file name, test name, failed (0/1), message
  local failure=""
  [[ $3 -eq 0 ]] || failure="<failure message=\"$(echo "$4" | tail -c 3000 | sed 's/&/\&amp;/g; s/</\&lt;/g; s/>/\&gt;/g; s/"/\&quot;/g')\"/>"
  cat >"$RESULTS/$1.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="downstream" tests="1" failures="$3" errors="0">
  <testcase classname="downstream" name="$2">$failure</testcase>
</testsuite>
XML
}

mild_source_devel  # CMAKE_PREFIX_PATH: the devel space, where find_package(catkin COMPONENTS mild_lcd) looks
log="$OUT.log"
if cmake -S "$PKG" -B "$OUT" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DPython3_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=OFF >"$log" 2>&1 &&
  cmake --build "$OUT" -j "$JOBS" >>"$log" 2>&1 &&
  "$OUT/devel/lib/mild_lcd_downstream_example/downstream_example" >>"$log" 2>&1; then
  junit downstream-package builds_and_runs_against_the_devel_space 0 ""
  grep '^downstream:' "$log"
else
  junit downstream-package builds_and_runs_against_the_devel_space 1 "$(cat "$log")"
  junit downstream-listeners the_readme_examples_print_accepted_loops 1 "the downstream package did not build"
  echo "[mild_lcd] the downstream package failed (see $log):" >&2
  tail -n 20 "$log" >&2
  exit 1
fi

# The examples of docs/interface.md ("Consuming LoopClosure"), run: a private master, each listener, one LoopClosure with an accepted and a
# rejected candidate; the listener must print the accepted one only.
problems=""
for f in src/loop_closure_listener.cpp scripts/loop_closure_listener.py; do
  /usr/bin/python3 - "$REPO/docs/interface.md" "$PKG/$f" <<'PY' || problems+="docs/interface.md does not show test/downstream_pkg/$f as it is; "
import sys
readme, code = (open(p, encoding="utf-8").read() for p in sys.argv[1:])
sys.exit(0 if code in readme else 1)
PY
done
mild_start_private_roscore "$OUT" || problems+="roscore did not start; "  # stopped on exit (common.sh)
listen() {  # name, command...: starts the listener, publishes one LoopClosure, checks what it printed
  local name=$1
  shift
  # Line-buffered: roscpp's log lines to a file would otherwise wait for the process to exit.
  stdbuf -oL "$@" loop_closure:=/mild_lcd/loop_closure >"$OUT/$name.log" 2>&1 &
  local pid=$!
  local ok=0
  for _ in $(seq 100); do
    rostopic info /mild_lcd/loop_closure 2>/dev/null | grep -q "Subscribers:" &&
      ! rostopic info /mild_lcd/loop_closure 2>/dev/null | grep -A1 "Subscribers:" | grep -q "None" && break
    sleep 0.2
  done
  rostopic pub -1 /mild_lcd/loop_closure mild_lcd/LoopClosure \
    "{query_id: 281, candidates: [{id: 28, accepted: true, probability: 0.99, inliers: 140, has_relative_pose: true,
      relative_translation: {x: 0.6, y: 0.0, z: 0.8}}, {id: 90, accepted: false, probability: 0.2}]}" >/dev/null 2>&1 || true
  for _ in $(seq 50); do
    grep -q "keyframe 281 closes a loop with 28 " "$OUT/$name.log" && ok=1 && break
    sleep 0.2
  done
  kill -INT "$pid" 2>/dev/null || true
  wait "$pid" || true
  grep -q "keyframe 281 closes a loop with 28 " "$OUT/$name.log" && ok=1
  if [[ $ok -ne 1 ]]; then
    problems+="$name did not print the accepted loop ($(tail -n 5 "$OUT/$name.log")); "
  elif grep -q "with 90 " "$OUT/$name.log"; then
    problems+="$name printed the rejected candidate; "
  elif ! grep -q "translation direction 0.6 0 0.8" "$OUT/$name.log"; then
    problems+="$name did not print the relative translation ($(tail -n 3 "$OUT/$name.log")); "
  fi
}
listen cpp_listener "$OUT/devel/lib/mild_lcd_downstream_example/loop_closure_listener"
listen python_listener /usr/bin/python3 -u "$PKG/scripts/loop_closure_listener.py"
if [[ -z "$problems" ]]; then
  junit downstream-listeners the_readme_examples_print_accepted_loops 0 ""
  echo "downstream: the C++ and Python LoopClosure examples of docs/interface.md print the accepted loop"
else
  junit downstream-listeners the_readme_examples_print_accepted_loops 1 "$problems"
  echo "[mild_lcd] the LoopClosure examples of docs/interface.md: $problems" >&2
  exit 1
fi
