#!/usr/bin/env bash
# Idempotent set-up for a fresh machine: a venv at the repository root with the client,
# the bridge (ROS 2 wheels of one distribution), the dev tools, the custom interfaces under
# msgs/interfaces built into the venv, and the npm peer client.
# Sourced by scripts/demo.sh and scripts/test.sh; safe to run again.
#
#   bash scripts/setup.sh                      # ROS 2 Jazzy (the default): .venv
#   ROS_DISTRO=kilted bash scripts/setup.sh    # ROS 2 Kilted: .venv-kilted
#
# Exports ROSLIBPY_LITE_VENV (the venv's path) and ROS_DISTRO for the scripts that source it.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PY="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*" >&2; }

# One distribution per venv: their wheels share names (ros-rclpy, ...) and do not mix.
export ROS_DISTRO="${ROS_DISTRO:-jazzy}"
case "$ROS_DISTRO" in
  jazzy) VENV_DIR=.venv; EXTRAS="bridge,build-interfaces" ;;
  kilted) VENV_DIR=.venv-kilted; EXTRAS="bridge-kilted,build-interfaces-kilted" ;;
  *) log "ROS_DISTRO=$ROS_DISTRO: this set-up knows jazzy (the default) and kilted" \
       "(docs/distributions.md)"; exit 2 ;;
esac

if [ ! -x "$VENV_DIR/bin/python" ]; then
  log "creating $VENV_DIR (ROS 2 $ROS_DISTRO)"
  "$PY" -m venv "$VENV_DIR"
fi
# shellcheck disable=SC1091
. "$VENV_DIR/bin/activate"
export VIRTUAL_ENV="$ROOT/$VENV_DIR"
export ROSLIBPY_LITE_VENV="$VIRTUAL_ENV"

stamp_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

dep_stamp="$(stamp_of pyproject.toml)"
if [ "$(cat "$VIRTUAL_ENV/.deps-stamp" 2>/dev/null)" != "$dep_stamp" ]; then
  log "installing Python packages (ROS 2 $ROS_DISTRO wheels, dev tools)"
  # (grep drops pip's notes about this machine's missing local index folders)
  if ! { python -m pip install -q --disable-pip-version-check --upgrade pip \
      && python -m pip install -q --disable-pip-version-check \
        -e ".[$EXTRAS,cbor,cli,dev,mcap,mcp]"; } 2>&1 \
    | { grep -v "^WARNING: Location .* is ignored" || true; }; then
    log "pip install failed"
    exit 1
  fi
  echo "$dep_stamp" > "$VIRTUAL_ENV/.deps-stamp"
fi

# Custom interfaces: CMake into the venv, rebuilt when their sources change (ours in
# msgs/interfaces; test fixtures in tests/interfaces, e.g. example_interfaces, not on PyPI).
VENV="$VIRTUAL_ENV" bash "$ROOT/scripts/build-interfaces.sh" msgs/interfaces tests/interfaces

# roslibpy's own upstream tests (its sdist), run against our bridge by the peer tests.
peer_src="$VIRTUAL_ENV/peer-src"
if [ ! -d "$peer_src/roslibpy-2.1.0/tests" ]; then
  log "fetching roslibpy 2.1.0's sources (its upstream tests)"
  mkdir -p "$peer_src"
  { python -m pip download -q --disable-pip-version-check --no-deps --no-binary :all: \
      roslibpy==2.1.0 -d "$peer_src" 2>&1 | { grep -v "^WARNING: Location .* is ignored" || true; }; } \
    && tar xzf "$peer_src/roslibpy-2.1.0.tar.gz" -C "$peer_src" \
    || { log "fetching roslibpy's sources failed"; exit 1; }
fi

# The stock npm client for the peer tests.
if [ -f tests/peers/node/package.json ] && command -v npm >/dev/null 2>&1; then
  npm_stamp="$(stamp_of tests/peers/node/package.json tests/peers/node/package-lock.json)"
  if [ ! -d tests/peers/node/node_modules ] || [ "$(cat "$VIRTUAL_ENV/.npm-stamp" 2>/dev/null)" != "$npm_stamp" ]; then
    log "installing the npm peer client (roslib)"
    (cd tests/peers/node && npm install --no-audit --no-fund --loglevel=error >/dev/null)
    echo "$npm_stamp" > "$VIRTUAL_ENV/.npm-stamp"
  fi
fi

# Chromium and its driver (Debian packages) for the status page's browser test.
if command -v apt-get >/dev/null 2>&1 \
    && ! { command -v chromium && command -v chromedriver; } >/dev/null 2>&1; then
  log "installing chromium and chromium-driver (apt-get)"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo -n"
  if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq \
      --no-install-recommends chromium chromium-driver; } > "$VIRTUAL_ENV/apt-chromium.log" 2>&1; then
    log "could not install chromium (the browser test will be skipped); see $VIRTUAL_ENV/apt-chromium.log"
  fi
fi

# HAProxy (a Debian package) for the fleet benchmark and its test: relays behind a real TCP
# load balancer (bench/fleet.py, tests/bench/test_fleet.py, deploy/haproxy/).
if command -v apt-get >/dev/null 2>&1 && ! command -v haproxy >/dev/null 2>&1 \
    && [ ! -x /usr/sbin/haproxy ]; then
  log "installing haproxy (apt-get)"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo -n"
  if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq \
      --no-install-recommends haproxy; } > /tmp/apt-haproxy.log 2>&1; then
    log "could not install haproxy (the fleet test will be skipped); see /tmp/apt-haproxy.log"
  fi
fi

# DDS stays on loopback for everything started from here.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
