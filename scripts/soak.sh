#!/bin/bash
# Soak test (not part of scripts/test.sh): the standalone node fed the embedded sample in a loop at
# 30 Hz (the 10 Hz bag played at 3x) for SOAK_SECONDS (600), on a private roscore. Reports memory
# growth per keyframe, queue drops and query-time drift (JSON in .build/soak/report.json).
#   ./scripts/soak.sh                      # 10 minutes, default parameters
#   SOAK_SECONDS=120 RATE=3 CONFIG=my.yaml ./scripts/soak.sh   # detector parameters from a YAML file
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

mild_install_deps
mild_configure_and_build --target mild_lcd_nodelet mild_lcd_node mild_bags
mild_source_devel

OUT="${SOAK_OUT:-$BUILD_DIR/soak}"
BAG="$BUILD_DIR/bags/sample_corridor.bag"
mkdir -p "$OUT"
mild_start_private_roscore "$OUT" || exit 1

[[ -z "${CONFIG:-}" ]] || rosparam load "$CONFIG" /mild_lcd
"$BUILD_DIR/devel/lib/mild_lcd/mild_lcd_node" __name:=mild_lcd image:=/camera/image _use_keyframe_input:=false \
  >"$OUT/node.log" 2>&1 &
NODE=$!
STARTED=("$NODE" "${STARTED[@]}")
until rostopic info /camera/image 2>/dev/null | grep -q mild_lcd; do sleep 0.2; done

rosbag play --quiet --loop -r "${RATE:-3}" "$BAG" --topics /camera/image >"$OUT/play.log" 2>&1 &
STARTED=($! "${STARTED[@]}")
echo "[mild_lcd] soak: ${SOAK_SECONDS:-600}s at $((10 * ${RATE:-3})) Hz; report in $OUT/report.json"
/usr/bin/python3 "$REPO/scripts/soak_monitor.py" _pid:="$NODE" _duration:="${SOAK_SECONDS:-600}" _report:="$OUT/report.json"
