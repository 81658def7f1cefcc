#!/bin/bash
# Builds the libFuzzer targets (test/fuzz) with clang, AddressSanitizer and UBSan in $BUILD_DIR/fuzz,
# replays the committed seeds and regression inputs, then fuzzes each target for FUZZ_SECONDS
# (default 30). Writes one JUnit result per target into $BUILD_DIR/test_results/mild_lcd, so that
# scripts/test.sh counts them; a crash input is kept in $BUILD_DIR/fuzz/artifacts.
#   FUZZ_SECONDS=600 ./scripts/fuzz.sh          # longer, by hand
#   ./scripts/fuzz.sh fuzz_database_file         # one target
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

TARGETS=("$@")
[[ ${#TARGETS[@]} -gt 0 ]] || TARGETS=(fuzz_database_file fuzz_keyframe_message fuzz_sparse_match_request)
SECONDS_EACH="${FUZZ_SECONDS:-30}"
FUZZ_DIR="$BUILD_DIR/fuzz"
RESULTS="$BUILD_DIR/test_results/mild_lcd"
mkdir -p "$FUZZ_DIR" "$RESULTS"

cmake -S "$REPO" -B "$FUZZ_DIR/build" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DMILD_FUZZ=ON \
  -DCATKIN_ENABLE_TESTING=OFF -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo >"$FUZZ_DIR/configure.log" 2>&1 || { cat "$FUZZ_DIR/configure.log"; exit 1; }
cmake --build "$FUZZ_DIR/build" -j "$JOBS" --target "${TARGETS[@]}"

junit() {  # name, failed (0/1), seconds, message
  local failure=""
  [[ $2 -eq 0 ]] || failure="<failure message=\"$(echo "$4" | sed 's/&/\&amp;/g; s/</\&lt;/g; s/"/\&quot;/g')\"/>"
  cat >"$RESULTS/fuzz-$1.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="fuzz" tests="1" failures="$2" errors="0" time="$3">
  <testcase classname="fuzz" name="$1" time="$3">$failure</testcase>
</testsuite>
XML
}

status=0
for target in "${TARGETS[@]}"; do
  work="$FUZZ_DIR/corpus/$target"
  artifacts="$FUZZ_DIR/artifacts/$target"
  mkdir -p "$work" "$artifacts"
  seeds=("$REPO/test/fuzz/corpus/$target")
  [[ -d "$REPO/test/fuzz/regressions/$target" ]] && seeds+=("$REPO/test/fuzz/regressions/$target")
  echo "[mild_lcd] fuzzing $target for ${SECONDS_EACH}s"
  start=$(date +%s)
  # New inputs go to the first (work) folder; the committed ones are read only.
  if "$FUZZ_DIR/build/devel/lib/mild_lcd/$target" -max_total_time="$SECONDS_EACH" -rss_limit_mb=2048 -timeout=20 \
      -artifact_prefix="$artifacts/" "$work" "${seeds[@]}" >"$FUZZ_DIR/$target.log" 2>&1; then
    junit "$target" 0 $(($(date +%s) - start)) ""
    grep -E '^Done' "$FUZZ_DIR/$target.log" || true
  else
    status=1
    junit "$target" 1 $(($(date +%s) - start)) "$(grep -m1 -E 'ERROR|runtime error|SUMMARY' "$FUZZ_DIR/$target.log")"
    echo "[mild_lcd] $target failed; input kept in $artifacts (log: $FUZZ_DIR/$target.log)" >&2
    grep -m5 -E 'ERROR|runtime error|SUMMARY' "$FUZZ_DIR/$target.log" >&2 || true
  fi
done
exit $status
