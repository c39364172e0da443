#!/usr/bin/env bash
# Build ROS 2 interface packages (.msg/.srv/.action, ament_cmake) into the bridge's virtual
# environment, so that the bridge knows their types:
#
#   scripts/build-interfaces.sh DIR...        # into $VIRTUAL_ENV, else the venv of `python`
#   VENV=/opt/roslibpy-lite/.venv scripts/build-interfaces.sh /path/to/robot_ws/src
#
# Each DIR is a package (it has package.xml) or a folder holding packages at any depth (a
# colcon workspace's src/); they are built in dependency order (catkin_pkg), as they come:
# no line of their CMakeLists.txt needs to change for the PyPI wheels. Needs the venv's
# `build-interfaces` extra, cmake, make and a C/C++ compiler. A package is built again only
# when its files change. PREFIX=DIR installs into DIR instead of the venv. Restart the bridge
# afterwards: it reads the installed types when it starts.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
log() { printf '[build-interfaces] %s\n' "$*" >&2; }

[ "$#" -gt 0 ] || { log "usage: $0 DIR... (interface packages, or folders of them)"; exit 2; }
VENV="${VENV:-${VIRTUAL_ENV:-$(python -c 'import sys; print(sys.prefix)' 2>/dev/null || true)}}"
PY="$VENV/bin/python"
[ -x "$PY" ] || { log "no virtual environment at '$VENV': set VENV=/path/to/.venv"; exit 2; }
PREFIX="${PREFIX:-$VENV}"
for dir in "$@"; do
  [ -d "$dir" ] || { log "$dir: no such folder"; exit 2; }
done
command -v cmake >/dev/null || { log "cmake is missing (apt-get install cmake g++ make)"; exit 2; }

# name<TAB>path of every package below the folders, in dependency order.
packages="$("$PY" - "$@" <<'PYEOF'
import sys
from pathlib import Path
try:
    from catkin_pkg.packages import find_packages
    from catkin_pkg.topological_order import topological_order_packages
except ImportError:
    sys.exit("catkin_pkg is missing: install the venv's build-interfaces extra")
found = {}
for root in sys.argv[1:]:
    root_path = Path(root).resolve()
    for rel, pkg in find_packages(str(root_path)).items():
        found[str(root_path / rel)] = pkg
for path, pkg in topological_order_packages(found):
    print(f"{pkg.name}\t{path}")
PYEOF
)" || { log "reading the packages failed"; exit 2; }
[ -n "$packages" ] || { log "no package.xml under $*"; exit 0; }

while IFS=$'\t' read -r name pkg; do
  src_stamp="$(find "$pkg" -type f | sort | xargs cat | sha256sum | cut -d' ' -f1)"
  if [ "$(cat "$PREFIX/.iface-$name" 2>/dev/null)" = "$src_stamp" ]; then
    continue
  fi
  log "building interface package $name into $PREFIX"
  bdir="$PREFIX/build/$name"
  rm -rf "$bdir"; mkdir -p "$bdir"
  (
    cd "$bdir"
    AMENT_PREFIX_PATH="$PREFIX:$VENV" CMAKE_PREFIX_PATH="$PREFIX:$VENV" \
      cmake "$pkg" -DPython3_EXECUTABLE="$PY" -DCMAKE_INSTALL_PREFIX="$PREFIX" \
      -DCMAKE_PROJECT_INCLUDE="$HERE/build-interfaces.cmake" -DBUILD_TESTING=OFF \
      > build.log 2>&1 \
      && make -j"$(nproc)" >> build.log 2>&1 && make install >> build.log 2>&1
  ) || { log "building $name failed; see $bdir/build.log"; tail -30 "$bdir/build.log" >&2; exit 1; }
  echo "$src_stamp" > "$PREFIX/.iface-$name"
done <<< "$packages"
