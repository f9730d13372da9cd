# shellcheck shell=bash
# Shared by scripts/test and scripts/demo: environment and the catkin workspace in build/ws.
#
# The workspace is <repo>/build/ws (build/ is git-ignored). Its src/active_tensegrity is a directory
# of symlinks, one per top-level entry of the repo except build/ and .git: a symlink to the repo root
# itself would contain build/ws/src/... again, a loop that rosrun's `find -L` over the package walks
# (and warns about) on every call. at_workspace keeps the links in step with the repo's top level.

AT_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
AT_BUILD="$AT_ROOT/build"
AT_WS="$AT_BUILD/ws"
AT_DEVEL="$AT_WS/devel"
AT_CATKIN_BUILD="$AT_WS/build"
AT_PYTHON=/usr/bin/python3
# the same cmake arguments on every catkin_make call, else catkin_make re-runs cmake each time
AT_CMAKE_ARGS=(-DCMAKE_BUILD_TYPE=Release "-DPYTHON_EXECUTABLE=$AT_PYTHON")
# scripts/test exports AT_WERROR=1: warnings are errors on the package's targets, in the scripts it runs too.
# (CMake keeps the option in build/ws's cache: later builds without it keep it on.)
if [[ "${AT_WERROR:-0}" == 1 ]]; then
  AT_CMAKE_ARGS+=(-DACTIVE_TENSEGRITY_WERROR=ON)
fi
AT_JOBS="${AT_JOBS:-2}"

# Debian's ROS lives in /usr: its python3 has catkin_pkg and rospy, a pyenv/venv python3 does not
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"
export ROS_HOSTNAME=localhost
unset ROS_IP
export ROS_HOME="$AT_BUILD/ros_home"
export ROS_LOG_DIR="$ROS_HOME/log"
export PYTHONDONTWRITEBYTECODE=1

at_log() { echo "== $*"; }

# Create build/ws with the package symlinked in, and drop a stale build tree (moved repo, other python).
at_workspace() {
  mkdir -p "$AT_WS/src" "$ROS_LOG_DIR"
  local pkg="$AT_WS/src/active_tensegrity"
  # the old layout: one symlink to the repo root
  [[ -L "$pkg" ]] && rm -f "$pkg"
  mkdir -p "$pkg"
  local entry name
  for entry in "$AT_ROOT"/* "$AT_ROOT"/.clang-format; do
    [[ -e "$entry" ]] || continue
    name="$(basename "$entry")"
    [[ "$name" == build ]] && continue
    if [[ "$(readlink "$pkg/$name" 2>/dev/null || true)" != "$entry" ]]; then
      ln -sfn "$entry" "$pkg/$name"
    fi
  done
  # links to entries the repo no longer has
  for entry in "$pkg"/* "$pkg"/.[!.]*; do
    if [[ -L "$entry" && ! -e "$entry" ]]; then
      rm -f "$entry"
    elif [[ -e "$entry" && ! -L "$entry" ]]; then
      echo "error: $entry is not a symlink; remove $AT_WS" >&2
      return 1
    fi
  done
  local cache="$AT_CATKIN_BUILD/CMakeCache.txt"
  if [[ -f "$cache" ]]; then
    local home python
    home="$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$cache")"
    python="$(sed -n 's/^PYTHON_EXECUTABLE:[A-Z]*=//p' "$cache")"
    if [[ "$home" != "$AT_WS/src" || "$python" != "$AT_PYTHON" ]]; then
      at_log "stale catkin build (source '$home', python '$python'): removing build/ws/build and build/ws/devel"
      rm -rf "$AT_CATKIN_BUILD" "$AT_DEVEL"
    fi
  fi
}

# at_side_workspace DIR: a second catkin folder on the same package folder as build/ws (DIR/src a symlink to
# build/ws/src), for builds with other flags (scripts/check_sanitizers, scripts/speed_report --generic).
at_side_workspace() {
  local dir=$1
  mkdir -p "$dir"
  if [[ "$(readlink "$dir/src" 2>/dev/null || true)" != "$AT_WS/src" ]]; then
    rm -rf "$dir/src"
    ln -s "$AT_WS/src" "$dir/src"
  fi
}

# catkin_make in build/ws; extra arguments are make targets, e.g. run_tests. Incremental when re-run.
# run_tests runs each test through build/catkin_generated/env_cached.sh, whose PYTHONPATH catkin computes
# when cmake first configures: on a fresh clone devel/lib/python3/dist-packages does not exist yet and is
# left out, and the rostest nodes cannot import this package's messages. It is put on PYTHONPATH here,
# before that first configure.
at_catkin_make() {
  PYTHONPATH="$AT_DEVEL/lib/python3/dist-packages${PYTHONPATH:+:$PYTHONPATH}" \
    catkin_make -C "$AT_WS" "-j$AT_JOBS" "${AT_CMAKE_ARGS[@]}" "$@"
}

# at_build [make targets...]
at_build() {
  at_workspace
  at_catkin_make "$@"
}

# devel/setup.bash reads unset variables and fails under `set -u`: source it with nounset off.
at_source_devel() {
  local had_u=0
  [[ $- == *u* ]] && had_u=1
  set +u
  # shellcheck disable=SC1091
  source "$AT_DEVEL/setup.bash"
  ((had_u)) && set -u
  return 0
}

# Processes a script started (stopped by at_stop_started, e.g. from `trap at_stop_started EXIT`).
AT_PIDS=()

# A master of the script's own on a free port (ROS_MASTER_URI exported); waits until it answers.
at_start_master() {
  local name="${1:-master}" port
  port="$("$AT_PYTHON" -c "import socket; s=socket.socket(); s.bind(('localhost', 0)); print(s.getsockname()[1])")"
  export ROS_MASTER_URI="http://localhost:$port"
  mkdir -p "$ROS_LOG_DIR"
  roscore -p "$port" >"$ROS_LOG_DIR/${name}_roscore.log" 2>&1 &
  AT_PIDS+=($!)
  local _
  for _ in $(seq 100); do
    rosparam list >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  echo "error: roscore on port $port did not answer (see $ROS_LOG_DIR/${name}_roscore.log)" >&2
  return 1
}

# SIGINT to everything in AT_PIDS (roslaunch and rosbag record close their files on it), then SIGKILL.
at_stop_started() {
  local pid
  for pid in "${AT_PIDS[@]+"${AT_PIDS[@]}"}"; do
    kill -INT "$pid" 2>/dev/null || true
  done
  for pid in "${AT_PIDS[@]+"${AT_PIDS[@]}"}"; do
    for _ in $(seq 50); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.2
    done
    kill -KILL "$pid" 2>/dev/null || true
  done
  AT_PIDS=()
}
