#!/bin/bash
# Accuracy on the bench sequences (../shared/bench by default), with the default parameters and two
# variants: without geometric verification, and with exact (brute-force) similarity instead of MIH.
# Prints a Markdown table; the candidates, stats and logs stay in $OUT.
#   ./scripts/bench_accuracy.sh [BENCH_DIR] [VARIANTS]
# VARIANTS, comma-separated: default, unverified, exact (the three by default), boundedN (unverified
# with index/max_bucket_entries N, e.g. bounded128).
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

BENCH="${1:-$REPO/../shared/bench}"
VARIANTS="${2:-default,unverified,exact}"
OUT="${OUT:-$BUILD_DIR/bench_accuracy}"
mild_configure_and_build --target mild_offline mild_score >/dev/null
BIN="$BUILD_DIR/devel/lib/mild_lcd"
mkdir -p "$OUT"

config_of() {
  case "$1" in
    default) : >"$OUT/default.yaml" ;;
    unverified) printf 'verification:\n  enabled: false\n' >"$OUT/unverified.yaml" ;;
    exact) printf 'verification:\n  enabled: false\nsimilarity:\n  search: exact\n' >"$OUT/exact.yaml" ;;
    bounded[0-9]*) printf 'verification:\n  enabled: false\nindex:\n  max_bucket_entries: %s\n' "${1#bounded}" >"$OUT/$1.yaml" ;;
    *) echo "unknown variant $1" >&2; exit 2 ;;
  esac
  echo "$OUT/$1.yaml"
}

echo "| sequence | variant | recall@100%P | AP | max F1 | extract ms | query ms | verify ms |"
echo "|---|---|---|---|---|---|---|---|"
for seq in "$BENCH"/*/; do
  seq="${seq%/}"
  name=$(basename "$seq")
  [[ -f "$seq/gt_loops.txt" ]] || continue
  for variant in ${VARIANTS//,/ }; do
    tag="${name}_${variant}"
    "$BIN/mild_offline" --images "$seq" --config "$(config_of "$variant")" --output "$OUT/$tag.csv" \
      --stats "$OUT/$tag.json" >"$OUT/$tag.log" 2>&1
    score=$("$BIN/mild_score" "$seq/gt_loops.txt" "$OUT/$tag.csv" --json)
    /usr/bin/python3 - "$name" "$variant" "$score" "$OUT/$tag.json" <<'EOF'
import json, sys
name, variant, score, stats = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.load(open(sys.argv[4]))
verify = stats.get("verify_ms", {}).get("mean")
print(f"| {name} | {variant} | {score['recall_at_100_precision']:.3f} | {score['average_precision']:.3f} | "
      f"{score['max_f1']:.3f} | {stats['extract_ms']['mean']:.1f} | {stats['query_ms']['mean']:.1f} | "
      f"{'-' if verify is None else f'{verify:.1f}'} |")
EOF
  done
done
