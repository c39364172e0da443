#!/usr/bin/env bash
# Mutation testing of one module against the tests meant to catch its faults (not run in CI):
#   bash scripts/mutate.sh bridge_server/security/names.py tests/security/test_probes.py::test_check_name_refuses_invalid_names
# MODULE is a .py file of the checkout; TESTS are pytest arguments (files, node ids, -k ...)
# as given from the repository root.
# mutmut (3.x) changes the module one small fault at a time (a flipped comparison, a constant
# off by one, a deleted call...) and runs the tests that reach the changed function: a mutant
# they fail on is killed; one that survives is a fault no test notices.
#
# It works on a copy of the checkout's files (tracked and untracked, not ignored) in
# $MUTATE_DIR (default: the system's temp directory), so the checkout gets no mutants/ folder
# and no mutmut settings; run it again on the same module and only changed functions are
# tested again. Afterwards, from that directory: `python -m mutmut results` lists the
# survivors, `python -m mutmut show NAME` shows one as a diff.
#
# MUTATE_JOBS: mutants tested at once (default 2: the machine is often shared).
# mutmut is installed into the venv on first use (it is not in the dev extra: libcst and
# textual are large and partly compiled).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ "$#" -lt 2 ]; then
    sed -n '2,5p' "$0" | sed 's/^# //' >&2
    exit 2
fi
MODULE="$(realpath -m --relative-to="$ROOT" "$1")"  # paths as from the repository root
shift
case "$MODULE" in
    *.py) ;;
    *) echo "mutate: MODULE must be a .py file of the checkout, got $MODULE" >&2; exit 2 ;;
esac
if [ ! -f "$ROOT/$MODULE" ]; then
    echo "mutate: no file $MODULE in $ROOT" >&2
    exit 2
fi
PYTHON="${PYTHON:-$ROOT/.venv/bin/python}"
if ! "$PYTHON" -c 'import mutmut' 2>/dev/null; then
    echo "[mutate] installing mutmut into $("$PYTHON" -c 'import sys; print(sys.prefix)')"
    "$PYTHON" -m pip install --quiet 'mutmut>=3.3,<4'
fi

SLUG="$(printf '%s' "$MODULE" | tr '/.' '__')"
WORK="${MUTATE_DIR:-${TMPDIR:-/tmp}/roslibpy-lite-mutate}/$SLUG"
mkdir -p "$WORK"
# A fresh copy of the sources each run; mutants/ (mutmut's results) is kept between runs
# with the same tests (mutmut then tests only the functions that changed).
find "$WORK" -mindepth 1 -maxdepth 1 ! -name mutants -exec rm -rf {} +
(cd "$ROOT" && git ls-files -z --cached --others --exclude-standard \
    | while IFS= read -r -d '' f; do if [ -e "$f" ]; then printf '%s\0' "$f"; fi; done \
    | xargs -0 cp --parents -p -t "$WORK")  # (a tracked file deleted here is left out)
cd "$WORK"
{
    echo "[mutmut]"
    echo "source_paths = $MODULE"
    # Everything else comes along: the tests import the whole package and its neighbours.
    echo "also_copy ="
    for entry in *; do
        [ "$entry" = mutants ] || echo "    $entry"
    done
    echo "pytest_add_cli_args_test_selection ="
    for arg in "$@"; do
        echo "    $arg"
    done
    echo "pytest_add_cli_args ="
    echo "    -p no:cacheprovider"
    # Each mutant's tests run in a process forked before any test ran: no state a clean
    # run left (names.py's cache of valid names, an rclpy context) leaks into them.
    echo "process_isolation = forkserver"
} >setup.cfg
if ! cmp -s setup.cfg mutants/setup.cfg; then
    rm -rf mutants  # other tests or settings: no earlier result holds
fi

# The mutants must be what the tests import: no PYTHONPATH pointing at the checkout.
unset PYTHONPATH
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}"
echo "[mutate] $MODULE against $* (in $WORK)"
"$PYTHON" -m mutmut run --max-children "${MUTATE_JOBS:-2}"
echo
echo "[mutate] not killed (python -m mutmut show NAME, from $WORK, shows one as a diff):"
"$PYTHON" -m mutmut results
echo "[mutate] $MODULE, mutants by outcome:"
"$PYTHON" -m mutmut results --all true | awk -F': ' '{print $NF}' | sort | uniq -c
