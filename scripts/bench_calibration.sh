#!/bin/bash
# Is the published probability a probability, on every kind of data, keyframe step and descriptor?
# Runs mild_offline (every candidate verified and written with its scorer features, --details
# --fit-every-candidate) over the bench's five public rendered sequences at keyframe steps 1, 2, 5
# and 10 and the two real ones at 1 and 2 (../shared/bench/subsample.py), once per descriptor
# (features/type orb, brisk, akaze; nothing else changed), then scripts/calibration_report.py
# prints: the ECE of each run by the bench's referee (../shared/bench/calibration.py), the ECE and
# accuracy of each run with the scorer refitted without its kind (real frames, each render kind,
# each descriptor, each step) and the reliability diagrams per kind (docs/reliability_*.png).
#   ./scripts/bench_calibration.sh                          # everything (about 45 minutes on two cores)
#   DESCRIPTORS=orb STEPS=1,2 ./scripts/bench_calibration.sh
#   CONFIG=my.yaml ./scripts/bench_calibration.sh           # another configuration (features/type is set per descriptor)
#   FIT=1 ./scripts/bench_calibration.sh                    # also print the scorer fitted on every run (the default's)
#   HOLDOUT_SEEDS= ./scripts/bench_calibration.sh           # without the never-fitted scenes (below)
# Besides, every kind is rendered again with seeds no fit has seen (HOLDOUT_SEEDS, 411 and 412: other
# rooms, routes and textures; rendered once into the cache) and run at the same steps: the report prints
# them apart, never fits on them, and they are what the probability does on scenes it was not fitted on.
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

BENCH="${BENCH:-$REPO/../shared/bench}"
CACHE="${MILD_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/mild_lcd/bench}"
OUT="${OUT:-$BUILD_DIR/bench_calibration}"
JOBS="${JOBS:-2}"
DESCRIPTORS="${DESCRIPTORS:-orb,brisk,akaze}"
STEPS="${STEPS:-1,2,5,10}"
PLOTS="${PLOTS:-$OUT}"
mild_install_deps
"$REPO/scripts/install_deps.sh" "$REPO/scripts/debian-packages-bench.txt"  # numpy, PyYAML (matplotlib: debian-packages.txt)
mild_configure_and_build --target mild_offline >/dev/null
BIN="$BUILD_DIR/devel/lib/mild_lcd"
mkdir -p "$OUT"

runs=()  # descriptor/name=folder
add() {  # source folder, name, step
  local dir
  dir=$(mild_step_sequence "$1" "$2" "$3")
  for d in ${DESCRIPTORS//,/ }; do runs+=("$d/${2}_k$3=$dir"); done
}
HOLDOUT_SEEDS="${HOLDOUT_SEEDS-411,412}"
for seed in ${HOLDOUT_SEEDS//,/ }; do
  for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do
    mild_render_generated "$CACHE" "${s}_s$seed" seq "$s" --seed "$seed"
  done
done
for k in ${STEPS//,/ }; do
  for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do add "$BENCH/$s" "$s" "$k"; done
  for seed in ${HOLDOUT_SEEDS//,/ }; do
    for s in pub_corridor pub_city pub_aliasing pub_campus pub_night; do add "$CACHE/${s}_s$seed" "${s}_s$seed" "$k"; done
  done
  if [[ $k -le 2 ]]; then
    for s in gp_day_a gp_night_a; do add "$BENCH/real/$s" "$s" "$k"; done
    # rtab_corridors is sparse already (84 keyframes): every 2nd leaves two loops to score.
    [[ $k -eq 1 ]] && add "$BENCH/real/rtab_corridors" rtab_corridors 1
  fi
done

for d in ${DESCRIPTORS//,/ }; do
  mkdir -p "$OUT/$d"
  # The user's configuration (or the defaults) with only features/type changed.
  /usr/bin/python3 -c 'import sys, yaml
config = yaml.safe_load(open(sys.argv[1])) if sys.argv[1] else None
config = config or {}
config.setdefault("features", {})["type"] = sys.argv[2]
yaml.safe_dump(config, sys.stdout)' "${CONFIG:-}" "$d" >"$OUT/$d/config.yaml"
done

export BIN OUT
run_one() {  # descriptor/name=folder
  local id=${1%%=*} dir=${1#*=}
  local d=${id%%/*}
  "$BIN/mild_offline" --images "$dir" --config "$OUT/$d/config.yaml" --output "$OUT/$id.csv" \
    --details "$OUT/$id.details.csv.tmp" --fit-every-candidate --stats "$OUT/$id.json" >"$OUT/$id.log" 2>&1 \
    || { echo "[mild_lcd] mild_offline failed on $id (see $OUT/$id.log)" >&2; return 1; }
  mv "$OUT/$id.details.csv.tmp" "$OUT/$id.details.csv"
}
export -f run_one
printf '%s\n' "${runs[@]}" | xargs -P "$JOBS" -I{} bash -c 'run_one "$@"' _ {}
fit=()
[[ -n "${FIT:-}" ]] && fit=(--fit)
/usr/bin/python3 "$REPO/scripts/calibration_report.py" --bench "$BENCH" --results "$OUT" --plots "$PLOTS" \
  --held-out-seeds "$HOLDOUT_SEEDS" "${fit[@]}" "${runs[@]}"
