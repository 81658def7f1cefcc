#!/bin/bash
# Installs missing Debian packages, builds mild_lcd in build/, and runs loop-closure detection on
# the embedded sample (sample/corridor: 300 frames of a ring corridor with one revisit), printing
# the loop closures it finds and the score against the sample's ground truth.
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

mild_install_deps
mild_configure_and_build --target mild_offline

SAMPLE="$REPO/sample/corridor"
OUT="$BUILD_DIR/demo"
mkdir -p "$OUT"
echo "[mild_lcd] offline run over $SAMPLE ($(ls "$SAMPLE/images" | wc -l) frames)"
"$BUILD_DIR/devel/lib/mild_lcd/mild_offline" --images "$SAMPLE" --gt "$SAMPLE/gt_loops.txt" \
  --output "$OUT/candidates.csv" --stats "$OUT/stats.json" --plots "$OUT"
echo "[mild_lcd] loop closures with probability >= 0.5 (query -> candidate):"
awk -F, 'NR > 1 && $3 >= 0.5 && !seen[$1]++ { printf "  %s -> %s  p=%.3f\n", $1, $2, $3 }' "$OUT/candidates.csv"
echo "[mild_lcd] candidates: $OUT/candidates.csv, plots: $OUT/pr_curve.png $OUT/loops_matrix.png, timing: $OUT/stats.json"
