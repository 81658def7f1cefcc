#!/bin/bash
# mild_lcd against the original MILD code (lhanaf/MILD), side by side on the same frames and ORB
# descriptors, one thread, passes alternated (src/tools/bench/original_mild_side_by_side.cpp says
# what is timed). Not part of scripts/test.sh: the original sources are not in this repository and
# this machine has no network; bring a checkout of https://github.com/lhanaf/MILD yourself.
#   ./scripts/bench_original_mild.sh /path/to/MILD                      # the five public sequences
#   ./scripts/bench_original_mild.sh /path/to/MILD ../shared/bench/pub_city/images 5
set -eo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

ORIGINAL="${1:?usage: $0 /path/to/lhanaf/MILD [IMAGE_DIR [PASSES]]}"
[[ -f "$ORIGINAL/MILD/loop_closure_detector.cpp" ]] || {
  echo "$ORIGINAL/MILD/loop_closure_detector.cpp: not found (a checkout of lhanaf/MILD is needed)" >&2
  exit 1
}

mild_install_deps
mild_configure_and_build --target mild_lcd_core

OUT="$BUILD_DIR/original_mild"
mkdir -p "$OUT/shim/opencv"
# The original includes OpenCV 3's <opencv/cv.h>, which OpenCV 4 no longer ships.
echo '#include <opencv2/opencv.hpp>' >"$OUT/shim/opencv/cv.h"
# -O3 -msse4.2: the original's own CMakeLists (Release, SSE 4.2 popcount).
g++ -std=c++17 -O3 -DNDEBUG -msse4.2 -w \
  -I"$OUT/shim" -I"$ORIGINAL" -I"$REPO/include" -I/usr/include/opencv4 -I/usr/include/eigen3 \
  "$REPO/src/tools/bench/original_mild_side_by_side.cpp" "$ORIGINAL/MILD/loop_closure_detector.cpp" \
  -o "$OUT/side_by_side" -L"$BUILD_DIR/devel/lib" -Wl,-rpath,"$BUILD_DIR/devel/lib" -lmild_lcd_core \
  -lopencv_core -lopencv_features2d -lopencv_imgcodecs -lopencv_imgproc

if [[ -n "${2:-}" ]]; then
  "$OUT/side_by_side" "$2" "${3:-3}"
else
  for seq in pub_corridor pub_night pub_aliasing pub_campus pub_city; do
    "$OUT/side_by_side" "$REPO/../shared/bench/$seq/images" "${3:-3}"
  done
fi
