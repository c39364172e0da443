#!/usr/bin/env bash
# The demo: a bridge, a simulated IMU (rclpy) and the sample roslibpy_lite program,
# all together, with their output prefixed per process. Ctrl+C stops everything.
#
#   bash scripts/demo.sh                 # bridge on ws://127.0.0.1:9090
#   PORT=9191 bash scripts/demo.sh       # another port (PORT=0: any free port)
#   IMU_RATE=5 bash scripts/demo.sh      # a calmer IMU (messages per second, default 50)
#   bash scripts/demo.sh -- --certfile server.pem --keyfile server.key --auth-file auth.toml
#                                        # a secured bridge: what follows -- goes to the bridge;
#                                        # the sample program reads $ROSLIBPY_LITE_TOKEN and
#                                        # $ROSLIBPY_LITE_CAFILE (SECURITY.md)
#
# Set-up on a fresh machine (venv, ROS 2 Jazzy wheels, interfaces) is done by
# scripts/setup.sh, sourced first; ROS_DISTRO=kilted runs it all on ROS 2 Kilted instead. DDS stays on loopback
# (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, exported by setup.sh).
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BRIDGE_ARGS=()
if [ "${1:-}" = "--" ]; then
  shift
  BRIDGE_ARGS=("$@")
  set --
fi
# shellcheck source=scripts/setup.sh
. "$ROOT/scripts/setup.sh"
set +e
cd "$ROOT"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export PYTHONUNBUFFERED=1
PORT="${PORT:-9090}"
HOST=127.0.0.1
# the venv setup.sh made for $ROS_DISTRO (.venv for Jazzy, .venv-kilted for Kilted)
PY="$ROSLIBPY_LITE_VENV/bin/python"
VREL="${ROSLIBPY_LITE_VENV#"$ROOT"/}"

say() { printf '[demo] %s\n' "$*"; }

# prefix TAG [READY_REGEX]: print each input line as "TAG | line"; the first line
# matching READY_REGEX is also written to fd 3 (the ready pipe), as is "exited" at EOF.
prefix() {
  local tag="$1" ready_re="${2:-}" line
  while IFS= read -r line || [ -n "$line" ]; do
    printf '%-9s | %s\n' "$tag" "$line"
    if [ -n "$ready_re" ] && [[ "$line" =~ $ready_re ]]; then
      printf '%s\n' "$line" >&3
      ready_re=""
    fi
  done
  [ -n "$ready_re" ] && printf 'exited\n' >&3
  return 0
}

tmp="$(mktemp -d)"
ready_fifo="$tmp/ready"
mkfifo "$ready_fifo"
exec 3<>"$ready_fifo" # read-write: opening never blocks
rm -rf "$tmp"

pids=()
names=()
stopping=0

stop_all() {
  # Stop in reverse order of start (program, IMU, bridge): SIGINT, then SIGKILL after 10 s.
  # (bash's wait has no timeout, so the deadline is polled.)
  local i pid n
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    pid="${pids[$i]}"
    kill -INT "$pid" 2>/dev/null || continue
    n=0
    while kill -0 "$pid" 2>/dev/null && [ "$n" -lt 100 ]; do
      sleep 0.1
      n=$((n + 1))
    done
    if kill -0 "$pid" 2>/dev/null; then
      say "${names[$i]} did not stop in 10 s; killing it"
      kill -KILL "$pid" 2>/dev/null
    fi
    wait "$pid" 2>/dev/null
  done
}

on_signal() {
  [ "$stopping" = 1 ] && return
  stopping=1
  echo
  say "stopping..."
  stop_all
  wait 2>/dev/null # the prefixers end at EOF
  say "demo stopped"
  exit 0
}
trap on_signal INT TERM

# start NAME READY_REGEX CMD...: run CMD in the background with prefixed output.
start() {
  local name="$1" ready_re="$2"
  shift 2
  # The prefixer ignores Ctrl+C and SIGTERM: it ends at EOF, after the last line.
  "$@" > >(trap '' INT TERM; prefix "$name" "$ready_re") 2>&1 &
  pids+=("$!")
  names+=("$name")
}

start bridge 'listening on wss?://' "$PY" -m bridge_server --host "$HOST" --port "$PORT" \
  ${BRIDGE_ARGS[@]+"${BRIDGE_ARGS[@]}"}
if ! IFS= read -r -t 60 -u 3 ready_line || [ "$ready_line" = exited ]; then
  say "the bridge did not start (is port $PORT already in use?)"
  stopping=1
  stop_all
  wait 2>/dev/null
  exit 1
fi
SCHEME=ws
if [[ "$ready_line" =~ (wss?)://[0-9.]+:([0-9]+) ]]; then
  SCHEME="${BASH_REMATCH[1]}"
  PORT="${BASH_REMATCH[2]}"
fi
URL="$SCHEME://$HOST:$PORT"

start imu_sim '' "$PY" -m examples.imu_sim --rate "${IMU_RATE:-50}"
start robot_app '' "$PY" -m examples.robot_app --url "$URL"

url_opt=""
{ [ "$PORT" != 9090 ] || [ "$SCHEME" != ws ]; } && url_opt=" --url $URL"
cat <<EOF
[demo] ------------------------------------------------------------------------
[demo] bridge on $URL; the IMU simulator and the sample program are running.
[demo] From another terminal (cd $ROOT), call the service:
[demo]   $VREL/bin/roslibpy-lite service call /mult_floats mult_msgs/srv/MultFloats "{x: 2.5, y: 4.0}"$url_opt
[demo] watch the counter:
[demo]   $VREL/bin/roslibpy-lite topic echo /example_counter --count 3$url_opt
[demo] send the IMU integrator a goal (Ctrl+C cancels it):
[demo]   $VREL/bin/roslibpy-lite action send_goal /integrate_imu mult_msgs/action/IntegrateImu "{seconds: 2.0}" --feedback$url_opt
[demo] or from Python ($VREL/bin/python):
[demo]   from roslibpy_lite import sync
[demo]   with sync.connect("$URL") as ros:
[demo]       goal = ros.send_goal("/integrate_imu", "mult_msgs/action/IntegrateImu", {"seconds": 2.0})
[demo]       print(goal.result(timeout=10).values)
[demo] or connect with stock roslibpy (pip install roslibpy):
[demo]   import roslibpy
[demo]   ros = roslibpy.Ros(host="$HOST", port=$PORT); ros.run()
[demo]   srv = roslibpy.Service(ros, "/mult_floats", "mult_msgs/srv/MultFloats")
[demo]   print(srv.call(roslibpy.ServiceRequest({"x": 2.5, "y": 4.0})))
[demo] Press Ctrl+C to stop everything.
[demo] ------------------------------------------------------------------------
EOF

# Run until Ctrl+C, or until one of the processes ends on its own.
while true; do
  wait -n "${pids[@]}"
  code=$?
  [ "$stopping" = 1 ] && break
  for i in "${!pids[@]}"; do
    if ! kill -0 "${pids[$i]}" 2>/dev/null; then
      say "${names[$i]} exited unexpectedly (status $code); stopping the rest"
      stopping=1
      stop_all
      wait 2>/dev/null
      exit 1
    fi
  done
done
