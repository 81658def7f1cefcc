#!/bin/bash
# The example back-end measured on sequences with ground truth (docs/pose_graph.md): for each public
# sequence of ../shared/bench and a 5,000-frame walk (generated once by ../shared/bench/generator/gen.py
# into ~/.cache/mild_lcd/bench/scale5k_s301, never into the repository), mild_pose_graph_eval runs the
# detector with the bench camera's intrinsics, makes odometry with drift from poses.txt, runs the pose
# graph, and reports ATE before / after / after with 5 % wrong loops and the update time; then the
# same loops under a second drift model (a pure heading random walk). Prints two Markdown tables.
#   ./scripts/bench_pose_graph.sh                 # everything (about 15 minutes on two cores)
#   SEQUENCES="pub_corridor" ./scripts/bench_pose_graph.sh
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
BENCH="${BENCH:-$REPO/../shared/bench}"
CACHE="${MILD_BENCH_CACHE:-$HOME/.cache/mild_lcd/bench}"
OUT="${OUT:-$CACHE/pose_graph}"
SEQUENCES="${SEQUENCES:-pub_corridor pub_city pub_aliasing pub_campus pub_night scale5k_s301}"
mkdir -p "$OUT"

mild_install_deps
mild_configure_and_build --target mild_pose_graph_eval

for s in $SEQUENCES; do
  dir="$BENCH/$s"
  if [[ $s == scale5k_s301 ]]; then
    dir="$CACHE/scale5k_s301"
    if [[ ! -f "$dir/poses.txt" ]]; then
      "$REPO/scripts/install_deps.sh" "$REPO/scripts/debian-packages-bench.txt"
      echo "[mild_lcd] generating the 5,000-frame walk into $dir (a few minutes)"
      (cd "$BENCH/generator" && /usr/bin/python3 gen.py scale --frames 5000 --seed 301 --out "$dir") >"$dir.log" 2>&1
    fi
  fi
  [[ -d "$dir" ]] || { echo "[mild_lcd] $dir: no such sequence" >&2; exit 1; }
  echo "[mild_lcd] $s"
  "$BUILD_DIR/devel/lib/mild_lcd/mild_pose_graph_eval" --sequence "$dir" --config "$REPO/config/bench_camera.yaml" \
    --save-loops "$OUT/$s.loops.csv" --json "$OUT/$s.json" --plot "$OUT/$s.png" | tee "$OUT/$s.txt"
  # The same loops, odometry with a pure heading random walk of 0.02 rad/sqrt(m) instead.
  "$BUILD_DIR/devel/lib/mild_lcd/mild_pose_graph_eval" --sequence "$dir" --load-loops "$OUT/$s.loops.csv" \
    --heading-bias 0 --heading-random-walk 0.02 --json "$OUT/$s.random_walk.json" >"$OUT/$s.random_walk.txt"
done

/usr/bin/python3 - "$OUT" $SEQUENCES <<'PY'
import json, sys
out, seqs = sys.argv[1], sys.argv[2:]
for suffix, title in (("", "default drift (1 % scale, 1 % noise, 0.002 rad/m bias, 0.01 rad/sqrt(m) random walk)"),
                      (".random_walk", "heading random walk 0.02 rad/sqrt(m), no bias")):
    print("\n" + title + "\n")
    print("| sequence | keyframes | length | loops | ATE odometry | ATE after | ratio | 5 % wrong: ATE | ratio | update p95 |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in seqs:
        j = json.load(open("%s/%s%s.json" % (out, s, suffix)))
        print("| %s | %d | %.0f m | %d | %.2f m | %.2f m | %.2f | %.2f m (%d wrong) | %.2f | %.1f ms |" % (
            s, j["keyframes"], j["length_m"], j["loops"], j["ate_before"], j["ate_after"], j["ratio"],
            j["ate_after_wrong"], j["wrong_loops"], j["ratio_wrong"], j["update_ms"]["p95"]))
PY
