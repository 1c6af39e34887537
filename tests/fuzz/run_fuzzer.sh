#!/usr/bin/env bash
# Runs one libFuzzer harness for ctest (tests/fuzz/CMakeLists.txt):
#   run_fuzzer.sh short|long HARNESS WORK_DIR SEED_DIR REGRESSION_DIR [libFuzzer flags...]
# The work corpus starts empty on every run (a fixed seed then gives the same run), the seed
# corpus and the minimised findings are read-only inputs. Prints the executions and edge
# coverage (docs/fuzzing.md); fails on any crash, leak, UB report, timeout or memory limit.
set -euo pipefail
mode=$1 harness=$2 work=$3 seeds=$4 regressions=$5
shift 5
rm -rf "$work"
mkdir -p "$work/corpus" "$work/artifacts"
inputs=("$seeds")
[ -d "$regressions" ] && inputs+=("$regressions")
log="$work/$mode.log"
# C allocations that fail return NULL as in production (a corrupt HDF5 file makes libhdf5 ask
# for 256 TB: it gets NULL and reports an error; tests/data/fuzz/fclib_local). C++ new still
# reports, and libFuzzer's -malloc_limit_mb (= rss limit) catches any allocation > 2 GB.
export ASAN_OPTIONS="allocator_may_return_null=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$(dirname "$0")/lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
set +e
"$harness" -artifact_prefix="$work/artifacts/" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048 \
  "$@" "$work/corpus" "${inputs[@]}" >"$log" 2>&1
status=$?
set -e
runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)
seconds=$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | grep -o 'in [0-9]*' | grep -o '[0-9]*' || true)
coverage=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -n 1 || true)
echo "$(basename "$harness") ($mode): ${runs:-?} executions in ${seconds:-?} s, ${coverage:-no coverage line}, corpus $(ls "$work/corpus" | wc -l) new inputs (log: $log)"
if [ "$status" -ne 0 ]; then
  tail -n 40 "$log"
  echo "FAILED: exit $status; the input is in $work/artifacts/ (minimise it with -minimize_crash=1)" >&2
  exit 1
fi
