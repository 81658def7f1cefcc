#!/bin/bash
# The README's rviz picture: `roslaunch mild_lcd slam_example.launch` on the sample bag with odometry,
# rviz (config/slam_example.rviz) on a virtual X server (Xvfb), a screenshot once the bag has played
# and the back-end has taken the last loop, written to docs/slam_example_rviz.png (or $1).
#   ./scripts/screenshot_rviz.sh [OUT.png]
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
OUT_PNG="${1:-$REPO/docs/slam_example_rviz.png}"
mild_install_deps
"$REPO/scripts/install_deps.sh" "$REPO/scripts/debian-packages-screenshot.txt"
mild_configure_and_build --target mild_lcd_generate_messages mild_lcd_nodelet mild_lcd_pose_graph_nodelet mild_bags
mild_source_devel
LOG="$BUILD_DIR/screenshot"
mkdir -p "$LOG"

STARTED=()
stop_started() {
  for pid in "${STARTED[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  for _ in $(seq 100); do
    alive=0
    for pid in "${STARTED[@]}"; do kill -0 "$pid" 2>/dev/null && alive=1; done
    [[ $alive -eq 0 ]] && break
    sleep 0.1
  done
  for pid in "${STARTED[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
  for pid in "${STARTED[@]}"; do wait "$pid" 2>/dev/null || true; done
}
trap stop_started EXIT

# A free display number and a private master, so that a running X server or roscore is left alone.
DISPLAY_NUMBER=99
while [[ -e /tmp/.X11-unix/X$DISPLAY_NUMBER || -e /tmp/.X$DISPLAY_NUMBER-lock ]]; do DISPLAY_NUMBER=$((DISPLAY_NUMBER + 1)); done
Xvfb ":$DISPLAY_NUMBER" -screen 0 1280x800x24 -nolisten tcp >"$LOG/xvfb.log" 2>&1 &
STARTED+=($!)
export DISPLAY=":$DISPLAY_NUMBER"
PORT=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI="http://localhost:$PORT"
roslaunch -p "$PORT" mild_lcd slam_example.launch bag:="$BUILD_DIR/bags/sample_corridor_odometry.bag" rate:=2 \
  >"$LOG/roslaunch.log" 2>&1 &
STARTED=("$!" "${STARTED[@]}")
# The player exits after the bag; the detector and the back-end then answer the last keyframes.
for _ in $(seq 600); do
  grep -q "\[player-[0-9]*\] process has finished cleanly" "$LOG/roslaunch.log" 2>/dev/null && break
  sleep 0.5
done
grep -q "\[player-[0-9]*\] process has finished cleanly" "$LOG/roslaunch.log" ||
  { echo "[mild_lcd] the bag did not finish playing (see $LOG/roslaunch.log)" >&2; exit 1; }
sleep 5
import -window root "$OUT_PNG"
echo "[mild_lcd] wrote $OUT_PNG"
