#!/bin/bash
# The example back-end under load (a table for docs/pose_graph.md): on a private roscore, a nodelet
# manager with mild_lcd/PoseGraphNodelet alone (base_frame base_link; no camera tf, so it falls back to
# a forward-looking camera at the base's origin), fed by mild_bench_backend: KEYFRAMES (12000) keyframes
# at RATE (40) Hz on the wall clock, each an odometry message then a LoopClosure, laps of a rectangle
# with a loop to an earlier lap wherever one passes within 1 m. Prints Markdown (the settings, the
# back-end's diagnostics every 1000 keyframes and at the end, a summary) on stdout, the build's output
# on stderr; logs in .build/bench_backend/. Exits non-zero when the back-end lost a keyframe without
# counting it, or its manager died.
#   ./scripts/bench_backend.sh                        # about 5 minutes
#   KEYFRAMES=2000 RATE=100 ./scripts/bench_backend.sh
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

mild_install_deps >&2
mild_configure_and_build --target mild_lcd_pose_graph_nodelet mild_bench_backend >&2
mild_source_devel

OUT="${BENCH_BACKEND_OUT:-$BUILD_DIR/bench_backend}"
KEYFRAMES="${KEYFRAMES:-12000}"
RATE="${RATE:-40}"
mkdir -p "$OUT"
mild_start_private_roscore "$OUT" || exit 1

rosrun nodelet nodelet manager __name:=bench_manager >"$OUT/manager.log" 2>&1 &
MANAGER=$!
STARTED=("$MANAGER" "${STARTED[@]}")
rosrun nodelet nodelet load mild_lcd/PoseGraphNodelet /bench_manager __name:=pose_graph _base_frame:=base_link \
  >"$OUT/pose_graph.log" 2>&1 &
STARTED=($! "${STARTED[@]}")

CPU=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
echo "### Example back-end under load ($(date -u +%Y-%m-%d), $(nproc) cores, $CPU)"
echo
status=0
# mild_bench_backend waits (60 s) for the back-end to subscribe and (30 s) for its first diagnostics.
"$BUILD_DIR/devel/lib/mild_lcd/mild_bench_backend" --keyframes "$KEYFRAMES" --rate "$RATE" 2>"$OUT/bench.err" \
  | tee "$OUT/bench.txt" || status=$?
if ! kill -0 "$MANAGER" 2>/dev/null; then
  echo "the nodelet manager died during the run (see $OUT/manager.log)"
  status=1
fi
if [[ $status -ne 0 ]]; then
  [[ -s "$OUT/bench.err" ]] && cat "$OUT/bench.err" >&2
  echo "[mild_lcd] bench_backend failed (exit $status); logs in $OUT" >&2
fi
exit $status
