#!/usr/bin/env bash
# Set up (if needed) and run every check: ruff, mypy --strict, the whole test suite.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/setup.sh
. "$ROOT/scripts/setup.sh"
cd "$ROOT"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
# One DDS domain per run, so concurrent runs on one machine do not meet.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}"
echo "[test] ruff"
ruff check roslibpy_lite bridge_server msgs examples bench tests docs/_hooks
echo "[test] mypy --strict"
mypy roslibpy_lite bridge_server msgs examples bench tests
echo "[test] mkdocs build --strict"
SITE="$(mktemp -d)"
trap 'rm -rf "$SITE"' EXIT
NO_MKDOCS_2_WARNING=1 mkdocs build --strict --quiet --site-dir "$SITE"
# The docs tests read this site instead of building their own (the same build, half a minute).
export ROSLIBPY_LITE_BUILT_SITE="$SITE"
# Two workers (pytest-xdist), each with its own DDS domain (tests/conftest.py), a file's tests
# on one worker: most of a test's time is waiting on another process, so two share the cores.
WORKERS="${ROSLIBPY_LITE_TEST_WORKERS:-2}"
echo "[test] pytest (ROS_DOMAIN_ID=$ROS_DOMAIN_ID, $WORKERS workers)"
python -m pytest -n "$WORKERS" --dist loadfile "$@"
