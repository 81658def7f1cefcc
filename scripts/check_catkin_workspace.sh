#!/bin/bash
# The ROS user's way: the repository as a package in a catkin workspace (ws/src/mild_lcd, a symlink),
# built with Debian's catkin_make, installed with catkin_make install, and launched from the install
# space: `roslaunch mild_lcd mild_lcd.launch` must bring the nodelet up (its services appear on a
# private master). Also builds test/downstream_pkg against the install space. The workspace is
# configured with -DMILD_WITH_FAISS=OFF: a build without faiss (and OpenMP). CI runs this after the
# README's two commands.
#   ./scripts/check_catkin_workspace.sh            # workspace in a new temporary folder
#   WS=/tmp/ws ./scripts/check_catkin_workspace.sh
set -eo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
JOBS="${JOBS:-$(nproc)}"
"$REPO/scripts/install_deps.sh"
WS="${WS:-$(mktemp -d /tmp/mild_lcd_ws.XXXXXX)}"
mkdir -p "$WS/src"
ln -sfn "$REPO" "$WS/src/mild_lcd"
cd "$WS"
export ROS_HOME="$WS/ros_home"
export ROS_LOG_DIR="$ROS_HOME/log"
ARGS=(-DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo
      -DCATKIN_ENABLE_TESTING=OFF -DMILD_WITH_FAISS=OFF)
echo "[mild_lcd] catkin workspace $WS: catkin_make, then catkin_make install (without faiss)"
catkin_make "${ARGS[@]}" -j"$JOBS" >"$WS/catkin_make.log" 2>&1 || { tail -n 40 "$WS/catkin_make.log"; exit 1; }
grep -q "without faiss" "$WS/catkin_make.log" || { echo "[mild_lcd] the configuration did not leave faiss out" >&2; exit 1; }
catkin_make "${ARGS[@]}" -j"$JOBS" install >"$WS/install.log" 2>&1 || { tail -n 40 "$WS/install.log"; exit 1; }
[[ ! -e "$WS/install/include/mild_lcd/ros" ]] || { echo "[mild_lcd] private headers (mild_lcd/ros) installed" >&2; exit 1; }

# From the install space only: a fresh shell environment with install/setup.bash.
PORT=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')
(
  # shellcheck disable=SC1091
  source "$WS/install/setup.bash"
  export ROS_MASTER_URI="http://localhost:$PORT"
  where=$(rospack find mild_lcd)
  [[ "$where" == "$WS/install/"* ]] || { echo "[mild_lcd] rospack finds mild_lcd in $where, not the install space" >&2; exit 1; }
  roslaunch -p "$PORT" mild_lcd mild_lcd.launch >"$WS/roslaunch.log" 2>&1 &
  launch=$!
  up=0
  for _ in $(seq 120); do
    if rosservice list 2>/dev/null | grep -q '^/reset$'; then up=1; break; fi
    sleep 0.5
  done
  kill -INT "$launch" 2>/dev/null || true
  wait "$launch" || true
  if [[ $up -ne 1 ]]; then
    echo "[mild_lcd] roslaunch mild_lcd mild_lcd.launch from the install space did not bring the nodelet up:" >&2
    tail -n 30 "$WS/roslaunch.log" >&2
    exit 1
  fi
  echo "[mild_lcd] roslaunch mild_lcd mild_lcd.launch from $WS/install: the nodelet is up (/reset advertised)"
  # Another package against the install space.
  cmake -S "$REPO/test/downstream_pkg" -B "$WS/downstream" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DPython3_EXECUTABLE=/usr/bin/python3 >"$WS/downstream.log" 2>&1 &&
    cmake --build "$WS/downstream" -j "$JOBS" >>"$WS/downstream.log" 2>&1 &&
    "$WS/downstream/devel/lib/mild_lcd_downstream_example/downstream_example" ||
    { echo "[mild_lcd] the downstream package failed against the install space:" >&2; tail -n 30 "$WS/downstream.log" >&2; exit 1; }
)
echo "[mild_lcd] catkin workspace: built, installed and launched"
