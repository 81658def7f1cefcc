#!/bin/bash
# Three mild_lcd stations on three hosts find the loops between their groups of robots, through an
# outage of one host's link, as one node serving all six robots does; then one station is restarted
# on its saved maps and rejoins without a loop lost or repeated.
#
# The hosts are network namespaces on one machine, joined by veth pairs to a bridge in a fourth
# namespace (the "switch"), so that cutting one host's link is `ip link set ... down` on its switch
# port, as a radio link lost in the field: that host's processes keep running and talking among
# themselves, they only lose the others (and the master, which runs on host 1).
#   host 1  10.231.0.1  roscore, station alpha (robot1 robot2), a recorder of every loop_closure topic
#   host 2  10.231.0.2  station bravo (robot3 robot4)
#   host 3  10.231.0.3  station charlie (robot5 robot6), a recorder of robot5's and robot6's topics
# Robot r replays frames [50(r-1), 50r) of sample/corridor as mild_lcd/Keyframe on /robotR/keyframe
# from its station's host. The sample's inter-robot loops are robot5 -> robot1 and robot6 -> robot1,
# robot2: charlie's robots revisit alpha's places, so the outage of charlie's link hides exactly the
# loops that matter. Schedule (seconds from t0; MILD_TEAM_* to change):
#   0    robots 1-5 play (1 keyframe per second: 50 s)
#   55   host 3's link is cut
#   60   robot6 plays, inside host 3 (its station still gets its keyframes; its revisit of alpha's
#        places is made while alpha cannot be reached)
#   125  the link is restored; then the stations are given time to catch up (settle)
# Then a restart: the last status of every station is kept (status_before_restart.json); charlie's
# node gets SIGTERM (it saves its maps and its ledger, <maps>/charlie.team_ledger.json, which must
# be there) and its station is started again on the same folder (persistent). Once it is heard again
# and the recorders listen to it, robot6 revisits its frames 250..299 a second time under new
# keyframe ids (1250..1299, a bag of their own) at 2 keyframes per second, and the stations settle;
# the checker's (f) compares the statuses before and after, and the second revisit's loops with the first's.
# Before all that, a reference: the same six bags into one node serving all six robots (no team link;
# every keyframe asks every map), alone in a namespace of its own on loopback, robots 1-5 at once
# and then robot6, at 5 keyframes per second. test/team/check_team.py compares the two runs with
# the sample's ground truth; a recorder's arrival times and the schedule (events.json) tell it
# which of robot6's keyframes were made during the outage.
#
# Needs root (namespaces) and the built devel space (BUILD_DIR, default .build). Takes ~5 minutes,
# on two cores. Nothing leaves the namespaces: every address is 127.0.0.1 or 10.231.0.x inside
# them, and nothing is routed out. Every namespace (with its veths) and every process in them is
# removed on exit, also on failure or Ctrl-C.
#   test/team/three_hosts.sh [--junit FILE] [--keep] [--key] [--roster]
#     --junit FILE  also write the verdict as a JUnit file of one test case,
#                   team.ThreeHostsWithAnOutageAndARestart
#                   (scripts/test.sh counts it from its test_results folder)
#     --keep        keep the work folder (logs, recordings) after a pass too; a failure always keeps it
#     --key         every station with one team key (~team/key_file: a file of the work folder, mode
#                   0600, made by openssl rand -hex 32): every team message authenticated, the
#                   restarted station's included; the JUnit test case is then ...WithAKey
#     --roster      with --key: station names bound to keys as well (each station's Ed25519 key,
#                   ~team/station_key_file, and the roster of the three, ~team/roster_dir, made by
#                   openssl genpkey in the work folder): every message signed by its station; the
#                   JUnit test case is then ...WithAKeyAndARoster
#   MILD_TEAM_BAGS=DIR             make the bags there once and reuse them (default: in the work folder);
#                                  empty it when mild_make_bag's features change
#   MILD_TEAM_STATION_CMD='...'    how a station starts (see STATION_CMD below)
#   MILD_TEAM_REFERENCE_ARGS='...' the reference node's private parameters besides robots and queue
#                                  (see REFERENCE_ARGS below)
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$REPO/.build}"
SAMPLE="$REPO/sample/corridor"
TEST_NAME="ThreeHostsWithAnOutageAndARestart"

JUNIT=""
KEEP=0
KEYED=0
KEY_FILE=""
ROSTER=0
ROSTER_DIR=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --junit) JUNIT="$2"; shift 2 ;;
    --keep) KEEP=1; shift ;;
    --key) KEYED=1; shift ;;
    --roster) ROSTER=1; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "three_hosts.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ $ROSTER == 1 && $KEYED == 0 ]] && { echo "three_hosts.sh: --roster goes with --key" >&2; exit 2; }
[[ $KEYED == 1 ]] && TEST_NAME="${TEST_NAME}WithAKey"
[[ $ROSTER == 1 ]] && TEST_NAME="${TEST_NAME}AndARoster"

# Schedule, in seconds from t0 (when every station, player and recorder is ready).
KEYFRAMES_PER_SECOND="${MILD_TEAM_KEYFRAMES_PER_SECOND:-1}"
CUT_AT="${MILD_TEAM_CUT_AT:-55}"
ROBOT6_AT="${MILD_TEAM_ROBOT6_AT:-60}"
RESTORE_AT="${MILD_TEAM_RESTORE_AT:-125}"
# After the restore: at least SETTLE seconds, then until no loop_closure arrived for QUIET seconds,
# at most SETTLE_MAX in all (the stations may exchange what the outage held back for a while).
SETTLE="${MILD_TEAM_SETTLE:-40}"
QUIET="${MILD_TEAM_QUIET:-10}"
SETTLE_MAX="${MILD_TEAM_SETTLE_MAX:-120}"
# Startup (roscore, stations, recorders, paused players) on two busy cores.
READY_TIMEOUT="${MILD_TEAM_READY_TIMEOUT:-120}"
# The reference plays faster (it has no outage to wait through) into a queue that holds every keyframe.
REFERENCE_KEYFRAMES_PER_SECOND="${MILD_TEAM_REFERENCE_KEYFRAMES_PER_SECOND:-5}"
REFERENCE_TIMEOUT="${MILD_TEAM_REFERENCE_TIMEOUT:-180}"
# The restart: how long the station may take to go down (saving) and to be heard again (loading).
RESTART_TIMEOUT="${MILD_TEAM_RESTART_TIMEOUT:-90}"
# robot6's second revisit: its frames under ids shifted by REVISIT_ID_OFFSET, played at this rate,
# then the stations settle as above (at least REVISIT_SETTLE s, QUIET s quiet, REVISIT_SETTLE_MAX s).
REVISIT_ID_OFFSET=1000
REVISIT_KEYFRAMES_PER_SECOND="${MILD_TEAM_REVISIT_KEYFRAMES_PER_SECOND:-2}"
REVISIT_SETTLE="${MILD_TEAM_REVISIT_SETTLE:-10}"
REVISIT_SETTLE_MAX="${MILD_TEAM_REVISIT_SETTLE_MAX:-60}"
RESTARTED=charlie  # the station restarted: host 3's, whose robot6 revisits

FRAMES_PER_ROBOT=50
ALL_ROBOTS=(robot1 robot2 robot3 robot4 robot5 robot6)
STATIONS=(alpha bravo charlie)
STATION_ROBOTS=("robot1 robot2" "robot3 robot4" "robot5 robot6")
HOST_IPS=(10.231.0.1 10.231.0.2 10.231.0.3)
MASTER_URI="http://${HOST_IPS[0]}:11311"
STATUS_TOPIC=/mild_team/status

# How a station starts, expanded (eval) into a command line run in the station's host, with
# STATION, ROBOTS ("robot1 robot2"), MAPS (an empty folder of its own in the work folder: the
# launch's default is under $HOME), STATION_KEY (its private key with --roster, else "") and
# MILD_LAUNCH_PREFIX (scripts/test.sh sets it under
# AddressSanitizer). Each process also gets a ROS_HOME of its own. It is stopped with SIGINT.
# shellcheck disable=SC2016  # expanded later, by eval
DEFAULT_STATION_CMD='roslaunch --wait mild_lcd mild_lcd_base_station.launch station:="$STATION" robots:="$ROBOTS" database_dir:="$MAPS" key_file:="$KEY_FILE" station_key_file:="$STATION_KEY" roster_dir:="$ROSTER_DIR" launch_prefix:="${MILD_LAUNCH_PREFIX:-}"'
STATION_CMD="${MILD_TEAM_STATION_CMD:-$DEFAULT_STATION_CMD}"
# The reference: one node, one map per robot, no station. By default each keyframe asks every
# other robot's map: with the node's default (one other map per keyframe, in turn) it asks a given
# map every fifth keyframe of six robots, and found right inter-group loops for 3 query keyframes
# of the sample's 68, too few for check (a) to mean anything; asking every map it found 60.
# MILD_TEAM_REFERENCE_ARGS= (empty) runs it with the node's defaults.
REFERENCE_ARGS="${MILD_TEAM_REFERENCE_ARGS-_detector/other_maps_per_keyframe:=0}"
REFERENCE_CMD="rosrun mild_lcd mild_lcd_node __name:=mild_lcd_reference _robots:=\"${ALL_ROBOTS[*]}\" _queue_size:=400 $REFERENCE_ARGS"

# Names unique to this run, so that two runs (or a crashed one's leftovers) never collide.
HOST_NS=("mildh1-$$" "mildh2-$$" "mildh3-$$")
SWITCH_NS="mildsw-$$"
REFERENCE_NS="mildref-$$"
OUR_NS=("${HOST_NS[@]}" "$SWITCH_NS" "$REFERENCE_NS")

STARTED_AT=$(date +%s)
STEP="start-up"          # what was being done: the failure message when the script stops early
REASON=""                # or why it stopped, when it knows (die)
VERDICT="failed"         # passed only when the checker says so
CHECK_OUTPUT=""          # the checker's report, for the JUnit file
WORK=""
declare -A PIDS=()       # name -> pid of what was started in a namespace, to signal it by name

# The verdict as JUnit: one test case; a failure carries the checker's report (or where the harness
# stopped). Written with Python for its XML escaping.
write_junit() {
  [[ -n "$JUNIT" ]] || return 0
  mkdir -p "$(dirname "$JUNIT")"
  local message="$1" details="$2"
  /usr/bin/python3 - "$JUNIT" "$TEST_NAME" "$VERDICT" "$(( $(date +%s) - STARTED_AT ))" "$message" "$details" <<'EOF'
import sys
import xml.etree.ElementTree as ET
path, name, verdict, seconds, message, details = sys.argv[1:]
suite = ET.Element("testsuite", name="team", tests="1", failures="0" if verdict == "passed" else "1",
                   errors="0", time=seconds)
case = ET.SubElement(suite, "testcase", classname="team", name=name, status="run", time=seconds)
if verdict != "passed":
    ET.SubElement(case, "failure", message=message, type="failure").text = details
ET.ElementTree(suite).write(path, encoding="utf-8", xml_declaration=True)
EOF
}

# Everything this script made goes, whatever the way out: processes in our namespaces (SIGTERM,
# then SIGKILL), then the namespaces, which take their veths and bridge with them (none of them
# was ever in the root namespace).
cleanup() {
  local status=$?
  trap - EXIT INT TERM
  set +e  # clean up as much as can be, whatever fails
  local ns pids signal
  for signal in TERM KILL; do
    for ns in "${OUR_NS[@]}"; do
      [[ -e "/run/netns/$ns" ]] || continue
      pids=$(ip netns pids "$ns" 2>/dev/null)
      # shellcheck disable=SC2086  # one pid per word
      [[ -z "$pids" ]] || kill "-$signal" $pids 2>/dev/null
    done
    [[ $signal == TERM ]] && for _ in $(seq 50); do
      pids=""
      for ns in "${OUR_NS[@]}"; do
        [[ -e "/run/netns/$ns" ]] && pids+=$(ip netns pids "$ns" 2>/dev/null || true)
      done
      [[ -z "$pids" ]] && break
      sleep 0.1
    done
  done
  for ns in "${OUR_NS[@]}"; do
    [[ -e "/run/netns/$ns" ]] && ip netns delete "$ns"
  done
  if [[ $VERDICT == passed ]]; then
    write_junit "" ""
    echo "team.$TEST_NAME: passed"
  else
    local message="${REASON:-stopped during: $STEP (exit status $status)}"
    [[ -n "$CHECK_OUTPUT" ]] && message="the check failed (details in the output)"
    write_junit "$message" "${CHECK_OUTPUT:-$message${WORK:+; logs in $WORK/logs}}"
    echo "team.$TEST_NAME: FAILED ($message)" >&2
  fi
  if [[ -n "$WORK" ]]; then
    if [[ $VERDICT == passed && $KEEP -eq 0 ]]; then rm -rf "$WORK"; else echo "work folder kept: $WORK" >&2; fi
  fi
  [[ $VERDICT == passed ]] || exit 1
}
trap cleanup EXIT
trap 'exit 130' INT TERM  # through cleanup

die() {
  REASON=$1
  echo "three_hosts.sh: $1" >&2
  exit 1
}

# Not a skip: a test that cannot run must not pass unnoticed in scripts/test.sh's count.
[[ $(id -u) -eq 0 ]] || die "needs root (network namespaces): not run"
for tool in ip roscore roslaunch rosbag; do
  command -v "$tool" >/dev/null || die "$tool not found"
done
MAKE_BAG="$BUILD_DIR/devel/lib/mild_lcd/mild_make_bag"
[[ -x "$MAKE_BAG" ]] || die "$MAKE_BAG not built"
set +u  # devel/setup.bash reads unset variables
# shellcheck disable=SC1091
source "$BUILD_DIR/devel/setup.bash"
set -u
export PATH="/usr/bin:$PATH"  # the ROS tools' Python is Debian's, not a pyenv one first on PATH

WORK=$(mktemp -d "${TMPDIR:-/tmp}/mild_team.XXXXXX")
mkdir -p "$WORK/logs" "$WORK/home"
if [[ $KEYED == 1 ]]; then
  KEY_FILE="$WORK/team.key"
  (umask 077 && openssl rand -hex 32 >"$KEY_FILE")
  echo "team key: $KEY_FILE"
fi
if [[ $ROSTER == 1 ]]; then
  ROSTER_DIR="$WORK/roster"
  mkdir -p "$ROSTER_DIR" "$WORK/station_keys"
  for station in "${STATIONS[@]}"; do
    (umask 077 && openssl genpkey -algorithm ed25519 -out "$WORK/station_keys/$station.pem")
    openssl pkey -in "$WORK/station_keys/$station.pem" -pubout -out "$ROSTER_DIR/$station.pub"
  done
  echo "station keys: $WORK/station_keys, roster: $ROSTER_DIR"
fi
BAGS="${MILD_TEAM_BAGS:-$WORK/bags}"
mkdir -p "$BAGS"
echo "work folder: $WORK"

# run_in NS NAME IP MASTER [--stdin FILE] CMD...: start CMD in namespace NS in the background, as a
# ROS process of that host (ROS_IP, its own ROS_HOME and log folder), output in logs/NAME.log.
run_in() {
  local ns=$1 name=$2 ip=$3 master=$4 stdin=/dev/null
  shift 4
  if [[ $1 == --stdin ]]; then stdin=$2; shift 2; fi
  mkdir -p "$WORK/home/$name"
  ip netns exec "$ns" env ROS_IP="$ip" ROS_MASTER_URI="$master" ROS_HOME="$WORK/home/$name" \
    ROS_LOG_DIR="$WORK/home/$name/log" "$@" <"$stdin" >"$WORK/logs/$name.log" 2>&1 &
  PIDS[$name]=$!
}

# poll_until TIMEOUT CMD...: poll CMD every 0.2 s; false after TIMEOUT seconds.
poll_until() {
  local deadline=$(( $(date +%s) + $1 ))
  shift
  until "$@"; do
    [[ $(date +%s) -lt $deadline ]] || return 1
    sleep 0.2
  done
}

# wait_until TIMEOUT WHAT CMD...: poll CMD every 0.2 s; fail naming WHAT after TIMEOUT seconds.
wait_until() {
  local timeout=$1 what=$2
  shift 2
  local deadline=$(( $(date +%s) + timeout ))
  until "$@"; do
    [[ $(date +%s) -lt $deadline ]] || die "timed out after ${timeout} s waiting for $what (logs: $WORK/logs)"
    sleep 0.2
  done
}

# stop NAME...: SIGINT (roslaunch, rospy and mild_lcd_node all stop cleanly on it), then wait up
# to 30 s; what is left is cleanup's.
stop() {
  local name pid
  for name in "$@"; do kill -INT "${PIDS[$name]}" 2>/dev/null || true; done
  for name in "$@"; do
    pid=${PIDS[$name]}
    for _ in $(seq 300); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
  done
}

master_up() {  # NS IP MASTER
  ip netns exec "$1" env ROS_IP="$2" ROS_MASTER_URI="$3" ROS_HOME="$WORK/home" rosparam get /rosdistro >/dev/null 2>&1
}

# Each player starts paused (--pause) and reads its keys from a FIFO that the script holds open:
# one space unpauses it at its scheduled time. Unlike rosbag's pause service this needs no master,
# so robot6 starts on time while its host is cut off from the master. --wait-for-subscribers: its
# station listens before the first keyframe.
declare -A PLAYER_KEYS=()  # key (the robot, or robot6_revisit) -> fd of its player's FIFO
bag_of() {  # ROBOT [ID_OFFSET]: the bag of the robot's frames, under ids shifted by ID_OFFSET
  local index=${1#robot} offset=${2:-0}
  local first=$(( (index - 1) * FRAMES_PER_ROBOT ))
  if [[ $offset -eq 0 ]]; then
    echo "$BAGS/$1-$first-$(( first + FRAMES_PER_ROBOT )).bag"
  else
    echo "$BAGS/$1-ids$(( first + offset ))-$(( first + offset + FRAMES_PER_ROBOT )).bag"
  fi
}
start_player() {  # NS NAME IP MASTER KEY BAG RATE
  local ns=$1 name=$2 ip=$3 master=$4 key=$5 bag=$6 rate=$7
  local fifo="$WORK/$name.keys" fd
  mkfifo "$fifo"
  exec {fd}<>"$fifo"  # read-write: opens without a reader, and the player never sees end-of-file
  PLAYER_KEYS[$key]=$fd
  run_in "$ns" "$name" "$ip" "$master" --stdin "$fifo" \
    rosrun rosbag play --pause --wait-for-subscribers -r "$rate" "$bag"
}
player_ready() { grep -q "Finished waiting for subscribers" "$WORK/logs/$1.log"; }
unpause() {  # KEY...
  local key fd
  for key in "$@"; do
    fd=${PLAYER_KEYS[$key]}
    printf ' ' >&"$fd"
    exec {fd}>&-
  done
}

# record NS NAME IP MASTER ROBOTS [STATUS_TOPIC]: a recorder of those robots' loop_closure topics
# into NAME.jsonl, which creates NAME.ready once it is connected to each, keeps the publishers it
# is connected to in NAME.connections.json and, with STATUS_TOPIC, each station's last status in
# NAME.latest_status.json.
record() {
  local status_args=()
  [[ -z "${6:-}" ]] || status_args=(--status "$6" --latest-status "$WORK/$2.latest_status.json")
  run_in "$1" "$2" "$3" "$4" /usr/bin/python3 "$HERE/record_loops.py" --out "$WORK/$2.jsonl" --label "$2" \
    --robots "$5" --ready "$WORK/$2.ready" --connections "$WORK/$2.connections.json" "${status_args[@]}"
}

# Loop closures received so far by the recorders named (their files' lines of kind loop).
loops_received() {
  local name total=0 n
  for name in "$@"; do
    n=$(grep -c '"kind": "loop"' "$WORK/$name.jsonl" 2>/dev/null || true)
    total=$(( total + ${n:-0} ))
  done
  echo "$total"
}

# Distinct keyframes answered on their own robot's topic: every keyframe is, once processed.
keyframes_answered() {  # FILE
  /usr/bin/python3 - "$1" <<'EOF'
import json, sys
seen = set()
for line in open(sys.argv[1], encoding="utf-8"):
    r = json.loads(line)
    if r["kind"] == "loop" and r["topic"] == f"/{r['query_robot']}/loop_closure":
        seen.add((r["query_robot"], r["query_id"]))
print(len(seen))
EOF
}

exited() {  # NAME...: none of them runs any more
  local name
  for name in "$@"; do ! kill -0 "${PIDS[$name]}" 2>/dev/null || return 1; done
}

# Sleeps that a signal ends at once (bash runs a trap only after its foreground command): the
# long waits of the schedule would otherwise hold Ctrl-C's cleanup back by up to a minute.
pause_for() {  # SECONDS
  sleep "$1" &
  wait $!
}

sleep_until() {  # EPOCH_SECONDS (fractional)
  pause_for "$(/usr/bin/python3 -c "import sys, time; print(max(0.0, float(sys.argv[1]) - time.time()))" "$1")"
}

event() {  # NAME: the wall-clock time of a scheduled action, for the checker
  echo "\"$1\": $(date +%s.%N)," >>"$WORK/events.part"
}

# settle MIN MAX: at least MIN seconds, then until no loop_closure reached a recorder for QUIET
# seconds, at most MAX seconds in all.
settle() {
  pause_for "$1"
  local deadline=$(( $(date +%s) + $2 - $1 ))
  local last_count quiet_since count
  last_count=$(loops_received host1 host3) quiet_since=$(date +%s)
  while [[ $(date +%s) -lt $deadline && $(( $(date +%s) - quiet_since )) -lt $QUIET ]]; do
    sleep 1
    count=$(loops_received host1 host3)
    if [[ $count -ne $last_count ]]; then last_count=$count quiet_since=$(date +%s); fi
  done
}

# The pid of STATION's node (named mild_lcd_STATION, as the launch file names it) in namespace NS.
station_node_pid() {  # NS STATION
  local pid
  for pid in $(ip netns pids "$1"); do
    if tr '\0' '\n' <"/proc/$pid/cmdline" 2>/dev/null | grep -qx "__name:=mild_lcd_$2"; then
      echo "$pid"
      return 0
    fi
  done
  return 1
}

# The host 1 recorder has a status of STATION that arrived after SINCE (epoch seconds).
heard_since() {  # STATION SINCE
  /usr/bin/python3 - "$WORK/host1.latest_status.json" "$1" "$2" <<'EOF'
import json, sys
path, station, since = sys.argv[1], sys.argv[2], float(sys.argv[3])
try:
    with open(path, encoding="utf-8") as f:
        latest = json.load(f)
except (OSError, ValueError):
    sys.exit(1)
sys.exit(0 if latest.get(station, {}).get("received", 0.0) > since else 1)
EOF
}

# Recorder NAME is connected to a publisher of each TOPIC, and to none of those it had in BEFORE
# (an earlier copy of its connections file): it listens to the restarted station.
reconnected() {  # NAME BEFORE TOPIC...
  /usr/bin/python3 - "$WORK/$1.connections.json" "$2" "${@:3}" <<'EOF'
import json, sys
now_path, before_path, topics = sys.argv[1], sys.argv[2], sys.argv[3:]
try:
    with open(now_path, encoding="utf-8") as f:
        now = json.load(f)
    with open(before_path, encoding="utf-8") as f:
        before = json.load(f)
except (OSError, ValueError):
    sys.exit(1)
sys.exit(0 if all(now.get(t) and not set(now[t]) & set(before.get(t, [])) for t in topics) else 1)
EOF
}

# --- bags -------------------------------------------------------------------------------------
STEP="making the bags"
# Each robot's frames under their own ids, and robot6's again under ids REVISIT_ID_OFFSET above,
# stamped 1000 s later (mild_make_bag's default start is 1000 s): its second revisit.
for robot in "${ALL_ROBOTS[@]}" robot6:$REVISIT_ID_OFFSET; do
  offset=${robot#*:} robot=${robot%:*}
  [[ $offset == "$robot" ]] && offset=0
  first=$(( (${robot#robot} - 1) * FRAMES_PER_ROBOT ))
  bag=$(bag_of "$robot" "$offset")
  [[ -s "$bag" ]] && continue
  "$MAKE_BAG" --images "$SAMPLE" --output "$bag.tmp" --keyframe-topic "/$robot/keyframe" \
    --frames "$first" "$(( first + FRAMES_PER_ROBOT ))" --keyframe-id-offset "$offset" \
    --start "$(( offset == 0 ? 1000 : 2000 ))" --no-images >>"$WORK/logs/make_bag.log" 2>&1
  mv "$bag.tmp" "$bag"
done
# rosbag play -r: the wanted keyframes per second over the sample's frame rate (times.txt).
FPS=$(awk 'NR == 1 { first = $1 } { last = $1; n = NR } END { printf "%.6f", (n - 1) / (last - first) }' "$SAMPLE/times.txt")
RATE=$(awk -v k="$KEYFRAMES_PER_SECOND" -v f="$FPS" 'BEGIN { printf "%.6f", k / f }')
REFERENCE_RATE=$(awk -v k="$REFERENCE_KEYFRAMES_PER_SECOND" -v f="$FPS" 'BEGIN { printf "%.6f", k / f }')
REVISIT_RATE=$(awk -v k="$REVISIT_KEYFRAMES_PER_SECOND" -v f="$FPS" 'BEGIN { printf "%.6f", k / f }')
echo "sample at $FPS frames/s: distributed run at rate $RATE, reference at $REFERENCE_RATE"

# --- reference: one node, six robots ----------------------------------------------------------
STEP="starting the reference run"
ip netns add "$REFERENCE_NS"
ip -n "$REFERENCE_NS" link set lo up
REF_MASTER="http://127.0.0.1:11311"
run_in "$REFERENCE_NS" ref_roscore 127.0.0.1 "$REF_MASTER" roscore
wait_until 60 "the reference's roscore" master_up "$REFERENCE_NS" 127.0.0.1 "$REF_MASTER"
reference_argv=()
eval "reference_argv=($REFERENCE_CMD)"
run_in "$REFERENCE_NS" ref_node 127.0.0.1 "$REF_MASTER" "${reference_argv[@]}"
record "$REFERENCE_NS" reference 127.0.0.1 "$REF_MASTER" "${ALL_ROBOTS[*]}"
for robot in "${ALL_ROBOTS[@]}"; do
  start_player "$REFERENCE_NS" "ref_play_$robot" 127.0.0.1 "$REF_MASTER" "$robot" "$(bag_of "$robot")" "$REFERENCE_RATE"
done
STEP="waiting for the reference node, recorder and players"
wait_until "$READY_TIMEOUT" "the reference recorder" test -e "$WORK/reference.ready"
for robot in "${ALL_ROBOTS[@]}"; do
  wait_until "$READY_TIMEOUT" "the reference's $robot player" player_ready "ref_play_$robot"
done
STEP="playing the reference run"
# Robots 1-5 at once, then robot6 (its revisit after the places it revisits are mapped, as in the
# distributed run).
unpause robot1 robot2 robot3 robot4 robot5
wait_until "$REFERENCE_TIMEOUT" "the reference's players of robots 1-5" \
  exited ref_play_robot1 ref_play_robot2 ref_play_robot3 ref_play_robot4 ref_play_robot5
unpause robot6
wait_until "$REFERENCE_TIMEOUT" "the reference's robot6 player" exited ref_play_robot6
reference_answered() { (( $(keyframes_answered "$WORK/reference.jsonl") >= ${#ALL_ROBOTS[@]} * FRAMES_PER_ROBOT )); }
wait_until "$REFERENCE_TIMEOUT" "the reference node to answer every keyframe" reference_answered
stop reference ref_node
stop ref_roscore
echo "reference: $(keyframes_answered "$WORK/reference.jsonl") keyframes answered"

# --- three hosts ------------------------------------------------------------------------------
STEP="making the three hosts"
ip netns add "$SWITCH_NS"
ip -n "$SWITCH_NS" link set lo up
ip -n "$SWITCH_NS" link add br0 type bridge
ip -n "$SWITCH_NS" link set br0 up
for i in 0 1 2; do
  ns=${HOST_NS[i]}
  ip netns add "$ns"
  ip -n "$ns" link set lo up
  # Made in place: the host's end is eth0 in the host, the switch's end portN on the bridge.
  ip link add eth0 netns "$ns" type veth peer name "port$(( i + 1 ))" netns "$SWITCH_NS"
  ip -n "$SWITCH_NS" link set "port$(( i + 1 ))" master br0
  ip -n "$SWITCH_NS" link set "port$(( i + 1 ))" up
  ip -n "$ns" addr add "${HOST_IPS[i]}/24" dev eth0
  ip -n "$ns" link set eth0 up
done

STEP="starting roscore, the stations, the recorders and the players"
run_in "${HOST_NS[0]}" roscore "${HOST_IPS[0]}" "$MASTER_URI" roscore
for i in 0 1 2; do
  wait_until 60 "the master from host $(( i + 1 ))" master_up "${HOST_NS[i]}" "${HOST_IPS[i]}" "$MASTER_URI"
done
start_station() {  # HOST_INDEX NAME: station STATIONS[HOST_INDEX] in its host, as process NAME
  local i=$1 station_argv=()
  # shellcheck disable=SC2034  # ROBOTS, MAPS and STATION_KEY are read by the eval of STATION_CMD
  local STATION=${STATIONS[i]} ROBOTS=${STATION_ROBOTS[i]} MAPS="$WORK/maps/${STATIONS[i]}" STATION_KEY=""
  [[ $ROSTER == 1 ]] && STATION_KEY="$WORK/station_keys/${STATIONS[i]}.pem"
  mkdir -p "$MAPS"
  eval "station_argv=($STATION_CMD)"
  run_in "${HOST_NS[i]}" "$2" "${HOST_IPS[i]}" "$MASTER_URI" "${station_argv[@]}"
}
for i in 0 1 2; do start_station "$i" "station_${STATIONS[i]}"; done
record "${HOST_NS[0]}" host1 "${HOST_IPS[0]}" "$MASTER_URI" "${ALL_ROBOTS[*]}" "$STATUS_TOPIC"
record "${HOST_NS[2]}" host3 "${HOST_IPS[2]}" "$MASTER_URI" "${STATION_ROBOTS[2]}"
for robot in "${ALL_ROBOTS[@]}"; do
  i=$(( (${robot#robot} - 1) / 2 ))  # robots 1-2 on host 1, 3-4 on host 2, 5-6 on host 3
  start_player "${HOST_NS[i]}" "play_$robot" "${HOST_IPS[i]}" "$MASTER_URI" "$robot" "$(bag_of "$robot")" "$RATE"
done
STEP="waiting for the stations, recorders and players"
wait_until "$READY_TIMEOUT" "the host 1 recorder" test -e "$WORK/host1.ready"
wait_until "$READY_TIMEOUT" "the host 3 recorder" test -e "$WORK/host3.ready"
for robot in "${ALL_ROBOTS[@]}"; do
  wait_until "$READY_TIMEOUT" "$robot's player" player_ready "play_$robot"
done

STEP="playing the schedule"
: >"$WORK/events.part"
T0=$(date +%s.%N)
event t0
unpause robot1 robot2 robot3 robot4 robot5
echo "t0: robots 1-5 play"
sleep_until "$(awk -v t="$T0" -v d="$CUT_AT" 'BEGIN { printf "%.3f", t + d }')"
ip -n "$SWITCH_NS" link set port3 down
event cut
echo "t0+$CUT_AT: host 3 cut off"
sleep_until "$(awk -v t="$T0" -v d="$ROBOT6_AT" 'BEGIN { printf "%.3f", t + d }')"
unpause robot6
event robot6_start
echo "t0+$ROBOT6_AT: robot6 plays"
sleep_until "$(awk -v t="$T0" -v d="$RESTORE_AT" 'BEGIN { printf "%.3f", t + d }')"
ip -n "$SWITCH_NS" link set port3 up
event restore
echo "t0+$RESTORE_AT: host 3 back"

STEP="letting the stations settle"
settle "$SETTLE" "$SETTLE_MAX"
event settled
echo "t0+$(awk -v t="$T0" -v now="$(date +%s.%N)" 'BEGIN { printf "%.0f", now - t }'): settled"

# --- restart ----------------------------------------------------------------------------------
# The station of host 3 is stopped as a service manager would (SIGTERM to its node, which saves
# its maps and ledger on the way down; its roslaunch then ends, having nothing left to run) and
# started again on the same folder, persistent: it must rejoin where it left.
STEP="restarting station $RESTARTED"
RESTART_HOST=2
[[ ${STATIONS[RESTART_HOST]} == "$RESTARTED" ]] || die "station $RESTARTED is not on host $(( RESTART_HOST + 1 ))"
LEDGER="$WORK/maps/$RESTARTED/$RESTARTED.team_ledger.json"
node_pid=$(station_node_pid "${HOST_NS[RESTART_HOST]}" "$RESTARTED") ||
  die "no process named __name:=mild_lcd_$RESTARTED in host $(( RESTART_HOST + 1 )) (a MILD_TEAM_STATION_CMD that names it otherwise?)"
# What every station said last, and who each recorder listens to, before the restart.
cp "$WORK/host1.latest_status.json" "$WORK/status_before_restart.json"
cp "$WORK/host1.connections.json" "$WORK/host1.connections_before_restart.json"
cp "$WORK/host3.connections.json" "$WORK/host3.connections_before_restart.json"
event restart_sigterm
sigterm_at=$(date +%s)
kill -TERM "$node_pid"
node_down() { ! kill -0 "$node_pid" 2>/dev/null; }
wait_until "$RESTART_TIMEOUT" "$RESTARTED's node to end after SIGTERM" node_down
launch_down() { exited "station_$RESTARTED"; }
# roslaunch ends once its only node has; if it does not, it is asked to.
poll_until 15 launch_down || stop "station_$RESTARTED"
event restart_down
[[ -s "$LEDGER" ]] || die "$RESTARTED saved no ledger on SIGTERM: $LEDGER is missing or empty"
(( $(stat -c %Y "$LEDGER") >= sigterm_at )) || die "$RESTARTED's ledger $LEDGER was not written on SIGTERM"
echo "$RESTARTED: SIGTERM, saved $(grep -c 'saved .* keyframes' "$WORK/logs/station_$RESTARTED.log" || true) maps and its ledger ($(stat -c %s "$LEDGER") bytes)"
start_station "$RESTART_HOST" "station_${RESTARTED}_restarted"
event restart_start
restart_start=$(date +%s.%N)
wait_until "$RESTART_TIMEOUT" "the restarted $RESTARTED's status" heard_since "$RESTARTED" "$restart_start"
# Answers published before a recorder connects to the new node would be lost to it.
restarted_topics=()
for robot in ${STATION_ROBOTS[RESTART_HOST]}; do restarted_topics+=("/$robot/loop_closure"); done
for name in host1 host3; do
  wait_until "$RESTART_TIMEOUT" "the $name recorder to connect to the restarted $RESTARTED" \
    reconnected "$name" "$WORK/$name.connections_before_restart.json" "${restarted_topics[@]}"
done
event restart_up
echo "$RESTARTED: heard again $(awk -v t="$restart_start" -v now="$(date +%s.%N)" 'BEGIN { printf "%.1f", now - t }') s after its start"

# --- second revisit ---------------------------------------------------------------------------
STEP="robot6's second revisit"
start_player "${HOST_NS[RESTART_HOST]}" play_robot6_revisit "${HOST_IPS[RESTART_HOST]}" "$MASTER_URI" \
  robot6_revisit "$(bag_of robot6 "$REVISIT_ID_OFFSET")" "$REVISIT_RATE"
wait_until "$READY_TIMEOUT" "robot6's second revisit player" player_ready play_robot6_revisit
unpause robot6_revisit
event revisit_start
echo "robot6 revisits again (ids $(( 250 + REVISIT_ID_OFFSET ))..$(( 299 + REVISIT_ID_OFFSET )), $REVISIT_KEYFRAMES_PER_SECOND keyframes/s)"
revisit_played() { exited play_robot6_revisit; }
wait_until "$(awk -v n="$FRAMES_PER_ROBOT" -v k="$REVISIT_KEYFRAMES_PER_SECOND" 'BEGIN { printf "%d", n / k + 60 }')" \
  "robot6's second revisit to be played" revisit_played
event revisit_end
settle "$REVISIT_SETTLE" "$REVISIT_SETTLE_MAX"
event stop
echo "t0+$(awk -v t="$T0" -v now="$(date +%s.%N)" 'BEGIN { printf "%.0f", now - t }'): stop"
for robot in "${ALL_ROBOTS[@]}"; do
  kill -0 "${PIDS[play_$robot]}" 2>/dev/null && echo "three_hosts.sh: $robot's player still runs at the end" >&2
done
stop host1 host3
stop station_alpha station_bravo "station_${RESTARTED}_restarted"
stop roscore
{ echo "{"; sed '$ s/,$//' "$WORK/events.part"; echo "}"; } >"$WORK/events.json"

# --- check ------------------------------------------------------------------------------------
STEP="checking the recordings"
set +e
bags=()
for robot in "${ALL_ROBOTS[@]}"; do bags+=("$(bag_of "$robot")"); done
CHECK_OUTPUT=$(/usr/bin/python3 "$HERE/check_team.py" --gt "$SAMPLE/gt_loops.txt" --reference "$WORK/reference.jsonl" \
  --distributed "$WORK/host1.jsonl" "$WORK/host3.jsonl" --events "$WORK/events.json" \
  --restarted "$RESTARTED" --status-before-restart "$WORK/status_before_restart.json" \
  --revisit-id-offset "$REVISIT_ID_OFFSET" --bags "${bags[@]}" 2>&1)
check_status=$?
set -e
echo "$CHECK_OUTPUT" | tee "$WORK/check.txt"
[[ $check_status -eq 0 ]] && VERDICT=passed
