# Shared by scripts/*.sh: install what is missing, then configure and build into build/.
# Sourced, not executed. Honours BUILD_DIR, BUILD_TYPE, JOBS, MILD_WERROR (ON: warnings are errors, as
# in CI; MILD_WERROR=OFF for another compiler) and MILD_CMAKE_ARGS.
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Not "build/": rosrun ignores executables under <package>/build/, and the repository root is the package.
export BUILD_DIR="${BUILD_DIR:-$REPO/.build}"
BUILD_TYPE="${BUILD_TYPE:-RelWithDebInfo}"
JOBS="${JOBS:-$(nproc)}"
export ROS_HOME="$BUILD_DIR/ros_home"
export ROS_LOG_DIR="$ROS_HOME/log"

mild_install_deps() {
  "$REPO/scripts/install_deps.sh"
}

# A sequence rendered by ../shared/bench/generator/gen.py into $1/$2, once (the cache outlives the
# build): $1 the cache, $2 its name, the rest gen.py's arguments. Needs BENCH.
mild_render_generated() {
  local cache=$1 name=$2
  shift 2
  [[ -f "$cache/$name/gt_loops.txt" ]] && return 0
  echo "[mild_lcd] rendering $name into $cache (once)" >&2
  mkdir -p "$cache"  # a fresh machine has no cache yet
  rm -rf "$cache/tmp_$name"
  (cd "$BENCH/generator" && /usr/bin/python3 gen.py "$@" --out "$cache/tmp_$name" >"$cache/$name.log" 2>&1) \
    || { echo "[mild_lcd] gen.py failed for $name (see $cache/$name.log)" >&2; return 1; }
  mv "$(find "$cache/tmp_$name" -name gt_loops.txt -printf '%h\n' | head -n 1)" "$cache/$name"
  rm -rf "$cache/tmp_$name"
}

# Every $3-th frame of the sequence in folder $1, subsampled by ../shared/bench/subsample.py into
# $CACHE/steps/$2_k$3 once (links; the cache outlives the build); prints that folder. Needs BENCH and
# CACHE.
mild_step_sequence() {
  local dir="$CACHE/steps/${2}_k$3"
  mkdir -p "$CACHE/steps"
  [[ -f "$dir/gt_loops.txt" ]] || /usr/bin/python3 "$BENCH/subsample.py" "$1" "$3" "$dir" >/dev/null || return 1
  echo "$dir"
}

mild_configure_and_build() {
  mkdir -p "$BUILD_DIR" "$ROS_HOME"
  # Debian's ROS tools need the system python, not the pyenv one first on PATH (ros-recipe gotcha 1/2).
  cmake -S "$REPO" -B "$BUILD_DIR" \
    -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 \
    -DCMAKE_BUILD_TYPE="$BUILD_TYPE" -DCATKIN_ENABLE_TESTING=ON -DMILD_WERROR="${MILD_WERROR:-ON}" ${MILD_CMAKE_ARGS:-} >"$BUILD_DIR/configure.log" 2>&1 \
    || { cat "$BUILD_DIR/configure.log"; return 1; }
  cmake --build "$BUILD_DIR" -j "$JOBS" "$@"
}

# devel/setup.bash puts this package on ROS_PACKAGE_PATH (needed by rospack, pluginlib, rostest).
# It references unset variables, so callers must not use `set -u`.
mild_source_devel() {
  # shellcheck disable=SC1091
  source "$BUILD_DIR/devel/setup.bash"
}

# A private master on a free port, so that a roscore the user already runs is left alone; its log
# goes to $1/roscore.log. Every process a script starts goes into STARTED (newest first where the
# order of stopping matters): on exit, each gets SIGINT (a clean stop), then whatever still runs
# after 15 s gets SIGTERM, then SIGKILL, so a hung node never outlives its script.
mild_start_private_roscore() {
  local out=$1
  PORT=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')
  export ROS_MASTER_URI="http://localhost:$PORT"
  STARTED=()
  trap mild_stop_started EXIT
  roscore -p "$PORT" >"$out/roscore.log" 2>&1 &
  STARTED+=($!)
  for _ in $(seq 100); do
    rosparam get /rosdistro >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  echo "[mild_lcd] roscore did not start (see $out/roscore.log)" >&2
  return 1
}

mild_stop_started() {
  for pid in "${STARTED[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  for _ in $(seq 150); do
    local alive=0
    for pid in "${STARTED[@]}"; do kill -0 "$pid" 2>/dev/null && alive=1; done
    [[ $alive -eq 0 ]] && break
    sleep 0.1
  done
  for pid in "${STARTED[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  sleep 1
  for pid in "${STARTED[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
  for pid in "${STARTED[@]}"; do wait "$pid" 2>/dev/null || true; done
}
