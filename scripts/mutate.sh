#!/usr/bin/env bash
# Mutation testing of modules against the tests meant to catch their faults (not run in CI):
#   bash scripts/mutate.sh rosbridge_core/security/names.py tests/security/test_probes.py::test_check_name_refuses_invalid_names
#   bash scripts/mutate.sh --list scripts/mutate-modules.txt
# MODULE is a .py file of the checkout, optionally MODULE::GLOB[,GLOB...] to mutate only
# the functions whose names match (e.g. bridge_server/zenoh/relay.py::*admit*); TESTS are
# pytest arguments (files, node ids, -k ...) as given from the repository root.
# --list FILE runs each line of FILE ("MODULE[::GLOB] TESTS...", quoted as in a shell;
# # comments) in turn.
# Either way it ends with one table: module, mutants, killed, time-outs, survived, no tests,
# other (suspicious, segfault, not checked) and the score, killed / (killed + survived):
# the share of the mutants a test reaches and that finish which the tests kill.
#
# mutmut (3.x) changes the module one small fault at a time (a flipped comparison, a constant
# off by one, a deleted call...) and runs the tests that reach the changed function: a mutant
# they fail on is killed; one that survives is a fault no test notices.
#
# It works on a copy of the checkout's files (tracked and untracked, not ignored) in
# $MUTATE_DIR (default: the system's temp directory), one folder per module, so the
# checkout gets no mutants/ folder and no mutmut settings; run it again on the same module
# and only changed functions are tested again (MUTATE_FRESH=1 tests every mutant again, as
# after tests were added or changed). Afterwards, from that module's folder (the
# run prints it): `python -m mutmut results` lists the survivors, `python -m mutmut show
# NAME` shows one as a diff.
#
# MUTATE_RERUN=1 tests again only the mutants that survived the last run (after tests were
# added to the files it ran; killed ones stay killed as long as no test was taken away,
# time-outs are counted apart).
# MUTATE_JOBS: mutants tested at once (default 2: the machine is often shared).
# mutmut is installed into the venv on first use (it is not in the dev extra: libcst and
# textual are large and partly compiled).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() {
    sed -n '2,8p' "$0" | sed 's/^# //' >&2
    exit 2
}
PYTHON="${PYTHON:-$ROOT/.venv/bin/python}"
TABLE="$(mktemp)"
trap 'rm -f "$TABLE"' EXIT

# count WORK DOTTED GLOBS: the row of counts of the module's mutants (those GLOBS match).
count() {
    (cd "$1" && "$PYTHON" -m mutmut results --all true) | "$PYTHON" -c '
import fnmatch, sys
dotted, globs = sys.argv[1], [g for g in sys.argv[2].split(",") if g]
counts = {"killed": 0, "timeout": 0, "survived": 0, "no tests": 0, "other": 0}
for line in sys.stdin:
    name, sep, status = line.strip().rpartition(": ")
    if not sep or not name.startswith(dotted + "."):
        continue
    if globs and not any(fnmatch.fnmatch(name, f"{dotted}.{g}") for g in globs):
        continue
    counts[status if status in counts else "other"] += 1
killed = counts["killed"]
reached = killed + counts["survived"]
score = f"{100 * killed / reached:.1f}%" if reached else "-"
print(sum(counts.values()), *counts.values(), score, sep="\t")
' "$2" "$3"
}

# mutate_one SPEC TESTS...: mutate one module (SPEC = MODULE[::GLOBS]) and add its row.
mutate_one() {
    local spec="$1" module globs slug work dotted started pattern=()
    shift
    module="${spec%%::*}"
    globs=""
    [ "$module" = "$spec" ] || globs="${spec#*::}"
    module="$(realpath -m --relative-to="$ROOT" "$module")"  # paths as from the repository root
    case "$module" in
        *.py) ;;
        *) echo "mutate: MODULE must be a .py file of the checkout, got $module" >&2; return 2 ;;
    esac
    if [ ! -f "$ROOT/$module" ]; then
        echo "mutate: no file $module in $ROOT" >&2
        return 2
    fi
    if [ "$#" -lt 1 ]; then
        echo "mutate: $module: name the tests to run" >&2
        return 2
    fi
    dotted="$(printf '%s' "${module%.py}" | tr '/' '.')"
    dotted="${dotted%.__init__}"
    if [ -n "$globs" ]; then
        IFS=',' read -r -a pattern <<<"$globs"
        pattern=("${pattern[@]/#/$dotted.}")
    fi
    slug="$(printf '%s' "$module" | tr '/.' '__')"
    work="${MUTATE_DIR:-${TMPDIR:-/tmp}/roslibpy-lite-mutate}/$slug"
    mkdir -p "$work"
    # A fresh copy of the sources each run; mutants/ (mutmut's results) is kept between runs
    # with the same tests (mutmut then tests only the functions that changed).
    find "$work" -mindepth 1 -maxdepth 1 ! -name mutants -exec rm -rf {} +
    (cd "$ROOT" && git ls-files -z --cached --others --exclude-standard \
        | while IFS= read -r -d '' f; do if [ -e "$f" ]; then printf '%s\0' "$f"; fi; done \
        | xargs -0 cp --parents -p -t "$work") || return 1  # (a tracked file deleted here is left out)
    {
        echo "[mutmut]"
        echo "source_paths = $module"
        # Everything else comes along: the tests import the whole package and its neighbours.
        echo "also_copy ="
        (cd "$work" && for entry in *; do
            [ "$entry" = mutants ] || [ "$entry" = setup.cfg ] || echo "    $entry"
        done)
        echo "pytest_add_cli_args_test_selection ="
        for arg in "$@"; do
            echo "    $arg"
        done
        echo "pytest_add_cli_args ="
        echo "    -p no:cacheprovider"
        # Each mutant's tests run in a process forked before any test ran: no state a clean
        # run left (names.py's cache of valid names, an rclpy context) leaks into them.
        echo "process_isolation = forkserver"
    } >"$work/setup.cfg.new"
    mv "$work/setup.cfg.new" "$work/setup.cfg"
    if [ -n "${MUTATE_FRESH:-}" ] || ! cmp -s "$work/setup.cfg" "$work/mutants/setup.cfg"; then
        rm -rf "$work/mutants"  # other tests or settings (or asked): no earlier result holds
    fi
    if [ -n "${MUTATE_RERUN:-}" ] && [ -d "$work/mutants" ]; then
        # Only what the last run did not kill, by name (mutmut tests a named mutant again).
        mapfile -t pattern < <(cd "$work" && "$PYTHON" -m mutmut results --all true \
            | "$PYTHON" -c '
import fnmatch, sys
dotted, globs = sys.argv[1], [g for g in sys.argv[2].split(",") if g]
for line in sys.stdin:
    name, _, status = line.strip().rpartition(": ")
    if status in ("survived", "suspicious") and name.startswith(dotted + ".") and (
            not globs or any(fnmatch.fnmatch(name, f"{dotted}.{g}") for g in globs)):
        print(name)
' "$dotted" "$globs")
        echo "[mutate] $spec: testing again the ${#pattern[@]} mutants that survived its last run"
        if [ "${#pattern[@]}" -eq 0 ]; then
            printf '%s\t%s\t0s\n' "$spec" "$(count "$work" "$dotted" "$globs")" >>"$TABLE"
            return 0
        fi
    fi
    echo "[mutate] $spec against $* (in $work)"
    started=$SECONDS
    # The mutants must be what the tests import: no PYTHONPATH pointing at the checkout.
    if ! (cd "$work" && unset PYTHONPATH && "$PYTHON" -m mutmut run \
            --max-children "${MUTATE_JOBS:-2}" ${pattern[@]+"${pattern[@]}"} </dev/null); then
        echo "mutate: mutmut failed on $spec" >&2
        return 1
    fi
    echo
    echo "[mutate] $spec: not killed (python -m mutmut show NAME, from $work, shows one as a diff):"
    (cd "$work" && "$PYTHON" -m mutmut results) | while IFS= read -r line; do
        name="${line%: *}"
        name="${name#"${name%%[![:space:]]*}"}"
        if [ -z "$globs" ]; then echo "$line"; continue; fi
        for p in "${pattern[@]}"; do
            # shellcheck disable=SC2053  # a glob, on purpose
            if [[ "$name" == $p ]]; then echo "$line"; break; fi
        done
    done
    printf '%s\t%s\t%ss\n' "$spec" "$(count "$work" "$dotted" "$globs")" \
        "$((SECONDS - started))" >>"$TABLE"
}

if ! "$PYTHON" -c 'import mutmut' 2>/dev/null; then
    echo "[mutate] installing mutmut into $("$PYTHON" -c 'import sys; print(sys.prefix)')"
    "$PYTHON" -m pip install --quiet 'mutmut>=3.3,<4'
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}"

if [ "${1:-}" = "--list" ]; then
    [ "$#" -eq 2 ] && [ -f "$2" ] || usage
    status=0
    while IFS= read -r -u 3 raw; do
        case "$raw" in ''|\#*) continue ;; esac
        # Split as a shell would, quotes kept together ("-k 'a or b'"), nothing expanded.
        mapfile -t line < <(printf '%s' "$raw" | xargs -n1 printf '%s\n')
        (cd "$ROOT" && mutate_one "${line[@]}") || {
            status=1
            printf '%s\tfailed (see above)\n' "${line[0]}" >>"$TABLE"
        }
    done 3<"$2"
else
    [ "$#" -ge 2 ] || usage
    status=0
    mutate_one "$@" || status=$?
fi
echo
{
    printf 'module\tmutants\tkilled\ttime-outs\tsurvived\tno tests\tother\tscore\ttime\n'
    cat "$TABLE"
} | column -t -s "$(printf '\t')"
exit "$status"
