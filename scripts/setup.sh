#!/usr/bin/env bash
# Idempotent set-up for a fresh machine: the .venv at the repository root with
# the client, the bridge (ROS 2 Jazzy wheels), the dev tools, the custom
# interfaces under msgs/interfaces built into the venv, and the npm peer client.
# Sourced by scripts/demo.sh and scripts/test.sh; safe to run again.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PY="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*" >&2; }

if [ ! -x .venv/bin/python ]; then
  log "creating .venv"
  "$PY" -m venv .venv
fi
# shellcheck disable=SC1091
. .venv/bin/activate
export VIRTUAL_ENV="$ROOT/.venv"

stamp_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

dep_stamp="$(stamp_of pyproject.toml)"
if [ "$(cat .venv/.deps-stamp 2>/dev/null)" != "$dep_stamp" ]; then
  log "installing Python packages (ROS 2 Jazzy wheels, dev tools)"
  # (grep drops pip's notes about this machine's missing local index folders)
  if ! { python -m pip install -q --disable-pip-version-check --upgrade pip \
      && python -m pip install -q --disable-pip-version-check \
        -e ".[bridge,build-interfaces,cbor,cli,dev,mcap,mcp]"; } 2>&1 \
    | { grep -v "^WARNING: Location .* is ignored" || true; }; then
    log "pip install failed"
    exit 1
  fi
  echo "$dep_stamp" > .venv/.deps-stamp
fi

# Custom interfaces: CMake into the venv, rebuilt when their sources change (ours in
# msgs/interfaces; test fixtures in tests/interfaces, e.g. example_interfaces, not on PyPI).
VENV="$VIRTUAL_ENV" bash "$ROOT/scripts/build-interfaces.sh" msgs/interfaces tests/interfaces

# roslibpy's own upstream tests (its sdist), run against our bridge by the peer tests.
if [ ! -d .venv/peer-src/roslibpy-2.1.0/tests ]; then
  log "fetching roslibpy 2.1.0's sources (its upstream tests)"
  mkdir -p .venv/peer-src
  { python -m pip download -q --disable-pip-version-check --no-deps --no-binary :all: \
      roslibpy==2.1.0 -d .venv/peer-src 2>&1 | { grep -v "^WARNING: Location .* is ignored" || true; }; } \
    && tar xzf .venv/peer-src/roslibpy-2.1.0.tar.gz -C .venv/peer-src \
    || { log "fetching roslibpy's sources failed"; exit 1; }
fi

# The stock npm client for the peer tests.
if [ -f tests/peers/node/package.json ] && command -v npm >/dev/null 2>&1; then
  npm_stamp="$(stamp_of tests/peers/node/package.json tests/peers/node/package-lock.json)"
  if [ ! -d tests/peers/node/node_modules ] || [ "$(cat .venv/.npm-stamp 2>/dev/null)" != "$npm_stamp" ]; then
    log "installing the npm peer client (roslib)"
    (cd tests/peers/node && npm install --no-audit --no-fund --loglevel=error >/dev/null)
    echo "$npm_stamp" > .venv/.npm-stamp
  fi
fi

# Chromium and its driver (Debian packages) for the status page's browser test.
if command -v apt-get >/dev/null 2>&1 \
    && ! { command -v chromium && command -v chromedriver; } >/dev/null 2>&1; then
  log "installing chromium and chromium-driver (apt-get)"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo -n"
  if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq \
      --no-install-recommends chromium chromium-driver; } > .venv/apt-chromium.log 2>&1; then
    log "could not install chromium (the browser test will be skipped); see .venv/apt-chromium.log"
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
