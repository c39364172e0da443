#!/usr/bin/env bash
# Set up (if needed) and run every check: ruff, mypy --strict, the whole test suite, on the
# ROS 2 distribution that ROS_DISTRO names (jazzy, the default, or kilted: scripts/setup.sh).
#
#   bash scripts/test.sh                      # Jazzy, in .venv
#   ROS_DISTRO=kilted bash scripts/test.sh    # Kilted, in .venv-kilted
#
# Under CI (CI=true) a Jazzy run is followed by the Kilted leg: the bridge's conformance,
# stock-peer and relay tests (KILTED_LEG_TESTS) on Kilted's wheels; ROSLIBPY_LITE_KILTED_LEG=0
# leaves it out, =1 runs it outside CI too. See docs/distributions.md.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

# What the Kilted leg runs: the bridge's rosbridge conformance, the stock peers (roslibpy and
# roslib.js) against it, the mixed-distribution tests and the relay with real Kilted robots.
# Left to the Jazzy run, to keep CI well under its budget: the other peer tests (client to
# client through the bridge, Foxglove, roslibpy's upstream tests) and the relay's
# type-budget tests (~6 min more on a loaded machine). See docs/distributions.md.
KILTED_LEG_TESTS=(
  tests/conformance
  tests/peers/test_stock.py
  tests/distro
  tests/relay/test_relay.py
  tests/relay/test_relay_actions.py
)

case "${CI:-}" in 1|true|yes) ci=1 ;; *) ci=0 ;; esac
KILTED_LEG="${ROSLIBPY_LITE_KILTED_LEG:-$ci}"

# shellcheck source=scripts/setup.sh
. "$ROOT/scripts/setup.sh"
cd "$ROOT"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
# One DDS domain per run, so concurrent runs on one machine do not meet.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}"
WORKERS="${ROSLIBPY_LITE_TEST_WORKERS:-2}"

if [ "${1:-}" = "--kilted-leg" ]; then
  # (the leg itself: run by the Jazzy run below, in a process of its own, with Kilted's venv)
  shift
  echo "[test] Kilted leg: pytest ${KILTED_LEG_TESTS[*]} (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
  exec python -m pytest -n "$WORKERS" --dist loadfile "${KILTED_LEG_TESTS[@]}" "$@"
fi

echo "[test] ROS 2 $ROS_DISTRO ($VIRTUAL_ENV)"
LEG=0
[ "$ROS_DISTRO" = jazzy ] && [ "$KILTED_LEG" = 1 ] && LEG=1
DISTRO_TESTS=()
if [ "$LEG" = 1 ]; then
  # Kilted's venv first: the Jazzy run's tests/distro start Kilted programs from it.
  start=$SECONDS
  echo "[test] Kilted leg: set-up of .venv-kilted (ROSLIBPY_LITE_KILTED_LEG=0 leaves the leg out)"
  ROS_DISTRO=kilted bash "$ROOT/scripts/setup.sh"
  echo "[test] Kilted leg: set-up took $(( SECONDS - start )) s"
elif [ "$ci" = 1 ] && [ ! -x "$ROOT/.venv-kilted/bin/python" ]; then
  # (under CI a skip fails: without the other venv tests/distro has nothing to pair with)
  DISTRO_TESTS=(--ignore=tests/distro)
fi
echo "[test] ruff"
ruff check roslibpy_lite rosbridge_core bridge_server msgs examples bench tests docs/_hooks
echo "[test] mypy --strict"
mypy roslibpy_lite rosbridge_core bridge_server msgs examples bench tests
echo "[test] mkdocs build --strict"
SITE="$(mktemp -d)"
trap 'rm -rf "$SITE"' EXIT
NO_MKDOCS_2_WARNING=1 mkdocs build --strict --quiet --site-dir "$SITE"
# The docs tests read this site instead of building their own (the same build, half a minute).
export ROSLIBPY_LITE_BUILT_SITE="$SITE"
# Two workers (pytest-xdist), each with its own DDS domain (tests/conftest.py), a file's tests
# on one worker: most of a test's time is waiting on another process, so two share the cores.
echo "[test] pytest (ROS_DISTRO=$ROS_DISTRO, ROS_DOMAIN_ID=$ROS_DOMAIN_ID, $WORKERS workers)"
rc=0
python -m pytest -n "$WORKERS" --dist loadfile "${DISTRO_TESTS[@]}" "$@" || rc=$?
if [ "$LEG" = 1 ]; then
  # Its own process, which activates .venv-kilted (set up above).
  start=$SECONDS
  ROS_DISTRO=kilted bash "$ROOT/scripts/test.sh" --kilted-leg || rc=$?
  echo "[test] Kilted leg: tests took $(( SECONDS - start )) s"
fi
exit "$rc"
