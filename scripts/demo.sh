#!/bin/bash
# The demo: installs missing Debian packages, builds mild_lcd in .build/, starts a private roscore
# (its own port, ROS_HOME inside .build/), replays the embedded sample as a rosbag (300 frames of a
# ring corridor with one revisit) through the nodelet, prints the loop closures as they arrive and
# the score against the sample's ground truth, and stops everything it started. Then it runs the
# offline runner over the same frames for the precision-recall plots.
#   RATE=1 ./scripts/demo.sh     # replay at the recorded 10 Hz (default: 2x)
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

mild_install_deps
# mild_lcd_generate_messages: the Python messages too, which the printer node imports.
mild_configure_and_build --target mild_lcd_generate_messages mild_lcd_nodelet mild_lcd_node mild_bags mild_score mild_offline
mild_source_devel

SAMPLE="$REPO/sample/corridor"
BAG="$BUILD_DIR/bags/sample_corridor.bag"
OUT="$BUILD_DIR/demo"
FRAMES=$(ls "$SAMPLE/images" | wc -l)
mkdir -p "$OUT"

mild_start_private_roscore "$OUT" || exit 1

rm -f "$OUT/replay_result.json"
: >"$OUT/roslaunch.log"  # exists before tail follows it
echo "[mild_lcd] replaying $BAG ($FRAMES keyframes) through mild_lcd/LoopClosureNodelet on $ROS_MASTER_URI"
roslaunch --wait mild_lcd replay.launch bag:="$BAG" image:=/camera/image rate:="${RATE:-2}" frames:="$FRAMES" \
  gt:="$SAMPLE/gt_loops.txt" output_csv:="$OUT/ros_candidates.csv" every_keyframe:=true \
  result_file:="$OUT/replay_result.json" >"$OUT/roslaunch.log" 2>&1 &
LAUNCH=$!
STARTED=("$LAUNCH" "${STARTED[@]}")
# The printer's lines (loop closures, score) as they arrive; roslaunch ends when the printer does.
tail -n +1 -f "$OUT/roslaunch.log" --pid="$LAUNCH" | grep --line-buffered -E '^(keyframe [0-9]+:|loop closure|processed|score|recall|average|max F1|loop queries|at the decision|only)'
wait "$LAUNCH" || true
# roslaunch exits 0 whatever its required printer did: the printer's own verdict decides.
if ! /usr/bin/python3 -c 'import json, sys; sys.exit(0 if json.load(open(sys.argv[1]))["ok"] else 1)' \
    "$OUT/replay_result.json" 2>/dev/null; then
  echo "[mild_lcd] the replay failed: not every keyframe was answered and scored (see $OUT/roslaunch.log)" >&2
  exit 1
fi
STARTED=("${STARTED[@]:1}")

echo "[mild_lcd] offline runner over the same frames, with plots"
"$BUILD_DIR/devel/lib/mild_lcd/mild_offline" --images "$SAMPLE" --gt "$SAMPLE/gt_loops.txt" \
  --output "$OUT/candidates.csv" --stats "$OUT/stats.json" --plots "$OUT" | grep -E '^(recall|average|max F1|at the decision)'
echo "[mild_lcd] outputs in $OUT: ros_candidates.csv, candidates.csv, pr_curve.png, loops_matrix.png, stats.json"
