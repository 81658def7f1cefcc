#!/bin/bash
# What each stage costs and what it buys (docs/speed.md, "What each stage costs"): one row per
# configuration that changes one thing from the defaults (features, FAST threshold, candidates
# verified, robust estimator, query budget, early stop, no verification), mild_offline on the real
# and public sequences of ../shared/bench one after another on one thread, then the defaults again
# (the run's noise). Prints a Markdown table: ms per stage, CPU per keyframe against the defaults,
# recall@100%P / AP on real and rendered frames. About 40 minutes on a quiet two-core machine.
#   ./scripts/bench_cost.sh                                  # every row, real + public sequences
#   ROWS="default,verification/method usac" ./scripts/bench_cost.sh
#   SEQUENCES="name=folder name=folder" ./scripts/bench_cost.sh   # other sequences (names gp_* count as real)
#   ROWS=frontier ./scripts/bench_cost.sh   # the cost-accuracy frontier of docs/accuracy.md: ORB at 800 / 1,500 /
#                                           # 3,000 features, BRISK, AKAZE (also 2 octaves, frames capped at
#                                           # 57,600 and 76,800 pixels, and the budget preset: capped at 76,800
#                                           # with one sub-level per octave) on the real sequences at keyframe
#                                           # steps 1 and 2 and the public ones at step 5
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

BENCH="${BENCH:-$REPO/../shared/bench}"
OUT="${OUT:-$BUILD_DIR/bench_cost}"
mild_install_deps
mild_configure_and_build --target mild_offline >/dev/null
CACHE="${MILD_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/mild_lcd/bench}"
step_of() {  # source folder, name, step: the subsampled sequence in the cache, "name_kstep=folder"
  local dir
  dir=$(mild_step_sequence "$1" "$2" "$3")
  echo "${2}_k$3=$dir"
}
if [[ -z "${SEQUENCES:-}" && "${ROWS:-}" == frontier ]]; then
  SEQUENCES=""
  for s in gp_day_a gp_night_a; do for k in 1 2; do SEQUENCES+=" $(step_of "$BENCH/real/$s" $s $k)"; done; done
  for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do SEQUENCES+=" $(step_of "$BENCH/$s" $s 5)"; done
fi
if [[ -z "${SEQUENCES:-}" ]]; then
  SEQUENCES="gp_day_a=$BENCH/real/gp_day_a gp_night_a=$BENCH/real/gp_night_a"
  for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do SEQUENCES+=" $s=$BENCH/$s"; done
fi
args=()
for s in $SEQUENCES; do args+=(--sequence "$s"); done
mkdir -p "$OUT"
# A copy of the binary: rebuilding while the table runs must not change the rows after it.
cp "$BUILD_DIR/devel/lib/mild_lcd/mild_offline" "$OUT/mild_offline"
/usr/bin/python3 "$REPO/scripts/cost_accuracy.py" --offline "$OUT/mild_offline" --out "$OUT" --rows "${ROWS:-}" "${args[@]}" \
  | tee "$OUT/cost.md"
echo "[mild_lcd] per-sequence figures in $OUT/cost.json" >&2
