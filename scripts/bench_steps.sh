#!/bin/bash
# The keyframe-step table: accuracy where a SLAM front-end's users live, at every K-th frame of the
# bench sequences (../shared/bench/subsample.py, the keyframe rates of ../shared/bench/PEERS_STEPS.md).
# The five public rendered sequences at steps 1, 2, 5 and 10, the real ones at 1 and 2, and the
# generated seeds 203 and 204 of every kind (rendered once into the cache; not in the shipped scorer's
# fit, which used the public five and the real sequences only) at step 5, each
# with the default configuration, scored by the rules of EVALUATION.md, beside the 2017 code's
# better variant and the best peer of PEERS.md / PEERS_STEPS.md and beside mild_lcd's own
# similarity top-1 (each query's most similar eligible keyframe, from --similarity): what the
# stages after retrieval add. Prints a Markdown table (docs/accuracy.md holds the last one).
#   ./scripts/bench_steps.sh                  # 2-3 minutes on two cores, plus rendering the seeds the first time
#   CONFIG=my.yaml ./scripts/bench_steps.sh   # another configuration
#   HOLDOUT=0 ./scripts/bench_steps.sh        # the bench's own sequences only
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

BENCH="${BENCH:-$REPO/../shared/bench}"
CACHE="${MILD_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/mild_lcd/bench}"
OUT="${OUT:-$BUILD_DIR/bench_steps}"
JOBS="${JOBS:-2}"
mild_install_deps
"$REPO/scripts/install_deps.sh" "$REPO/scripts/debian-packages-bench.txt"  # the generator's OpenCV and numpy
mild_configure_and_build --target mild_offline >/dev/null
BIN="$BUILD_DIR/devel/lib/mild_lcd"
mkdir -p "$OUT"

runs=()
add() {  # source folder, name, step: the subsampled sequence (symlinks, in the cache)
  local dir
  dir=$(mild_step_sequence "$1" "$2" "$3")
  runs+=("${2}_k$3=$dir")
}
for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do
  for k in 1 2 5 10; do add "$BENCH/$s" "$s" "$k"; done
done
for s in gp_day_a gp_night_a; do
  for k in 1 2; do add "$BENCH/real/$s" "$s" "$k"; done
done
if [[ "${HOLDOUT:-1}" != 0 ]]; then
  for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do
    for seed in 203 204; do
      mild_render_generated "$CACHE" "${s}_s$seed" seq "$s" --seed "$seed"
      add "$CACHE/${s}_s$seed" "${s}_s$seed" 5
    done
  done
fi

config=()
[[ -n "${CONFIG:-}" ]] && config=(--config "$CONFIG")
export BIN OUT CONFIG_ARGS="${config[*]}"
run_one() {  # name=folder
  local name=${1%%=*} dir=${1#*=}
  local config=($CONFIG_ARGS)
  "$BIN/mild_offline" --images "$dir" "${config[@]}" --output "$OUT/$name.csv" --similarity "$OUT/$name.npy" \
    >"$OUT/$name.log" 2>&1 || { echo "[mild_lcd] mild_offline failed on $name (see $OUT/$name.log)" >&2; return 1; }
}
export -f run_one
printf '%s\n' "${runs[@]}" | xargs -P "$JOBS" -I{} bash -c 'run_one "$@"' _ {}
/usr/bin/python3 "$REPO/scripts/step_table.py" "$BENCH" "$OUT" "${runs[@]}"
