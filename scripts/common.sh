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
