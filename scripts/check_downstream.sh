#!/bin/bash
# A package of someone else's, the catkin way: builds test/downstream_pkg (find_package(catkin
# COMPONENTS mild_lcd), mild_lcd's public headers, exported libraries and messages) against the devel
# space in $BUILD_DIR, runs its program, and writes the verdict as a JUnit result that
# scripts/test.sh counts. Needs a built $BUILD_DIR (scripts/test.sh runs it after the build).
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RESULTS="$BUILD_DIR/test_results/mild_lcd"
OUT="$BUILD_DIR/downstream"
mkdir -p "$RESULTS"
rm -rf "$OUT"

junit() {  # failed (0/1), message
  local failure=""
  [[ $1 -eq 0 ]] || failure="<failure message=\"$(echo "$2" | tail -c 3000 | sed 's/&/\&amp;/g; s/</\&lt;/g; s/"/\&quot;/g')\"/>"
  cat >"$RESULTS/downstream-package.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="downstream" tests="1" failures="$1" errors="0">
  <testcase classname="downstream" name="builds_and_runs_against_the_devel_space">$failure</testcase>
</testsuite>
XML
}

mild_source_devel  # CMAKE_PREFIX_PATH: the devel space, where find_package(catkin COMPONENTS mild_lcd) looks
log="$OUT.log"
if cmake -S "$REPO/test/downstream_pkg" -B "$OUT" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DPython3_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=OFF >"$log" 2>&1 &&
  cmake --build "$OUT" -j "$JOBS" >>"$log" 2>&1 &&
  "$OUT/devel/lib/mild_lcd_downstream_example/downstream_example" >>"$log" 2>&1; then
  junit 0 ""
  grep '^downstream:' "$log"
else
  junit 1 "$(cat "$log")"
  echo "[mild_lcd] the downstream package failed (see $log):" >&2
  tail -n 20 "$log" >&2
  exit 1
fi
