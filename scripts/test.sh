#!/bin/bash
# Installs missing Debian packages, builds mild_lcd in build/, runs every gtest and rostest and
# prints `N passed, N failed` as its last line. Exits non-zero when anything failed or did not build.
#   ./scripts/test.sh                       # everything
#   BUILD_DIR=build-asan MILD_CMAKE_ARGS=-DMILD_SANITIZE=address,undefined ./scripts/test.sh
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

fail() {
  echo "$1" >&2
  echo "0 passed, 1 failed"
  exit 1
}

mild_install_deps || fail "[mild_lcd] could not install the Debian packages it needs"
mild_configure_and_build || fail "[mild_lcd] build failed"
cmake --build "$BUILD_DIR" -j "$JOBS" --target tests || fail "[mild_lcd] test build failed"

rm -rf "$BUILD_DIR/test_results"
# run_tests exits 0 even when tests fail (ros-recipe gotcha 6): the verdict comes from the results.
cmake --build "$BUILD_DIR" --target run_tests -j 1 || true

verdict=0
catkin_test_results "$BUILD_DIR/test_results" >"$BUILD_DIR/catkin_test_results.txt" 2>&1 || verdict=$?
summary=$("$REPO/scripts/summarize_test_results.py" "$BUILD_DIR/test_results" --list-failures)
echo "$summary" | grep '^FAILED' || true
last=$(echo "$summary" | tail -n 1)
if [[ "$last" =~ ^([0-9]+)\ passed,\ ([0-9]+)\ failed$ ]]; then
  passed=${BASH_REMATCH[1]}
  failed=${BASH_REMATCH[2]}
else
  passed=0 failed=1
fi
if [[ $verdict -ne 0 && $failed -eq 0 ]]; then failed=1; fi   # catkin saw a failure we did not count
if [[ $passed -eq 0 && $failed -eq 0 ]]; then failed=1; fi     # nothing ran is not a pass
echo "$passed passed, $failed failed"
[[ $failed -eq 0 ]]
