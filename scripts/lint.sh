#!/bin/bash
# Static checks of the tree: catkin_lint (package.xml and CMakeLists.txt, default level: no errors
# or warnings) and clang-format (.clang-format; every tracked C++ file already formatted). Writes one
# JUnit result per check into $BUILD_DIR/test_results/mild_lcd, so that scripts/test.sh counts them.
#   ./scripts/lint.sh                                            # both checks
#   clang-format -i $(git ls-files '*.cpp' '*.hpp')              # to format the tree
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RESULTS="$BUILD_DIR/test_results/mild_lcd"
mkdir -p "$RESULTS"

junit() {  # name, failed (0/1), message
  local failure=""
  [[ $2 -eq 0 ]] || failure="<failure message=\"$(echo "$3" | head -c 2000 | sed 's/&/\&amp;/g; s/</\&lt;/g; s/"/\&quot;/g')\"/>"
  cat >"$RESULTS/lint-$1.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="lint" tests="1" failures="$2" errors="0">
  <testcase classname="lint" name="$1">$failure</testcase>
</testsuite>
XML
}

status=0
# catkin_lint exits 0 with warnings; any line it prints (other than the summary) is a finding.
lint_out=$(catkin_lint -q -W1 "$REPO" 2>&1) || true
if [[ -z "$lint_out" ]]; then
  junit catkin_lint 0 ""
else
  status=1
  junit catkin_lint 1 "$lint_out"
  echo "[mild_lcd] catkin_lint:" >&2
  echo "$lint_out" >&2
fi

cd "$REPO"
mapfile -t sources < <(git ls-files '*.cpp' '*.hpp' 2>/dev/null || find include src test -name '*.[ch]pp')
unformatted=()
for f in "${sources[@]}"; do
  clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || unformatted+=("$f")
done
if [[ ${#unformatted[@]} -eq 0 ]]; then
  junit clang_format 0 ""
else
  status=1
  junit clang_format 1 "not formatted: ${unformatted[*]}"
  echo "[mild_lcd] not formatted (clang-format -i FILE): ${unformatted[*]}" >&2
fi
exit $status
