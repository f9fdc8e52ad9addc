#!/usr/bin/env bash
# Run the slipest libFuzzer targets (SLCAN parser, COBS decoder, sample push, model image, raw frames into
# the node, payload parser, model-store operations, CANopen node operations) under ASan+UBSan and print the executions of each.
#   scripts/fuzz.sh [SECONDS] [BUILD_DIR]     short mode: every target for SECONDS
#                                             (default $FLEETLAB_FUZZ_SECONDS or 60), in parallel
#   scripts/fuzz.sh --long [EXECS] [BUILD_DIR] long mode: every target until EXECS executions
#                                             (default $FUZZ_EXECS or 10000000), one after the
#                                             other on one core; MERGES each target's campaign into
#                                             $FUZZ_STATS (default BUILD_DIR/fuzz-stats.json): the
#                                             other targets' entries stay (scripts/fuzz_stats.py)
#   FUZZ_TARGETS="fuzz_push fuzz_cobs" scripts/fuzz.sh ...   only these targets (default: all)
#   FUZZ_MAX_SECONDS=N scripts/fuzz.sh --long ...  also stop each target after N seconds (recorded
#                                             with the executions it reached)
#   FUZZ_BUNDLE=DIR scripts/fuzz.sh ...       build for that bundle (default: the example SN-S one); a
#                                             layer-table bundle (SN-D, any hidden sizes) adds
#                                             fuzz_image_table, and the store fuzzers start from its
#                                             format-2 model.img: e.g. FUZZ_TARGETS="fuzz_image_table fuzz_store"
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
MODE=short
if [[ "${1:-}" == "--long" ]]; then
  MODE=long
  shift
  EXECS="${1:-${FUZZ_EXECS:-10000000}}"
else
  SECONDS_PER_TARGET="${1:-${FLEETLAB_FUZZ_SECONDS:-60}}"
fi
BUILD="${2:-$ROOT/build/fuzz}"
STATS="${FUZZ_STATS:-$BUILD/fuzz-stats.json}"
TARGETS=(fuzz_payload fuzz_node_frames fuzz_image fuzz_cobs fuzz_slcan fuzz_push fuzz_store fuzz_co_frames)
if [[ -n "${FUZZ_TARGETS:-}" ]]; then
  read -r -a TARGETS <<<"$FUZZ_TARGETS"
fi
PY="${PYTHON:-$(command -v python3 || command -v python)}"

command -v clang >/dev/null || { echo "fuzz.sh: clang not found (scripts/setup.sh installs it)" >&2; exit 2; }
BUNDLE="${FUZZ_BUNDLE:-$ROOT/firmware_c/bundles/example}"
[[ -f "$BUNDLE/model.img" ]] || { echo "fuzz.sh: no model.img in FUZZ_BUNDLE=$BUNDLE" >&2; exit 2; }
cmake -S "$ROOT" -B "$BUILD" -DCMAKE_C_COMPILER=clang -DSLIPEST_FUZZ=ON -DSLIPEST_BUNDLE="$BUNDLE" \
  -DPython3_EXECUTABLE="$PY" >/dev/null
cmake --build "$BUILD" -j2 --target "${TARGETS[@]}" >/dev/null

LOGS="$BUILD/fuzz-logs"
mkdir -p "$LOGS"

run_one() { # target, extra libFuzzer options...; crashes leave a reproducer in $LOGS
  local t="$1"; shift
  mkdir -p "$BUILD/corpus/$t"
  # seed: a valid image, so that mutations start past the magic, sizes and CRC
  if [[ "$t" = fuzz_image || "$t" = fuzz_image_table ]] && [ -z "$(ls -A "$BUILD/corpus/$t")" ]; then
    cp "$BUNDLE/model.img" "$BUILD/corpus/$t/seed.img"
  fi
  local max_len=4096
  if [ "$t" = fuzz_image_table ]; then  # room for the seed image (a layer-table image may be ~80 KB)
    max_len=$(( $(stat -c %s "$BUNDLE/model.img") + 64 ))
  fi
  "$BUILD/$t" "$@" -max_len="$max_len" -print_final_stats=1 -artifact_prefix="$LOGS/$t-" \
      "$BUILD/corpus/$t" >"$LOGS/$t.log" 2>&1
}
report_fail() {
  echo "FAIL $1: see $LOGS/$1.log" >&2
  tail -20 "$LOGS/$1.log" >&2
}

record() { # target, seconds, clean: one line for the caller, one entry in $STATS
  local execs
  execs=$(grep -E "stat::number_of_executed_units" "$LOGS/$1.log" | awk '{print $2}')
  echo "$1 executions=${execs:-0} seconds=$2"
  "$PY" "$ROOT/scripts/fuzz_stats.py" record "$STATS" "$1" "$LOGS/$1.log" "$2" "$3" --mode "$MODE"
}

status=0
if [[ "$MODE" == short ]]; then
  rm -f "$STATS" # a short run is a fresh record of all its targets
  pids=()
  for t in "${TARGETS[@]}"; do
    run_one "$t" -max_total_time="$SECONDS_PER_TARGET" &
    pids+=($!)
  done
  for i in "${!TARGETS[@]}"; do
    ok=true
    wait "${pids[$i]}" || { report_fail "${TARGETS[$i]}"; status=1; ok=false; }
    record "${TARGETS[$i]}" "$SECONDS_PER_TARGET" "$ok"
  done
else
  limit=()
  [[ -n "${FUZZ_MAX_SECONDS:-}" ]] && limit=(-max_total_time="$FUZZ_MAX_SECONDS")
  for t in "${TARGETS[@]}"; do
    start=$(date +%s)
    ok=true
    run_one "$t" -runs="$EXECS" "${limit[@]}" || { report_fail "$t"; status=1; ok=false; }
    record "$t" $(( $(date +%s) - start )) "$ok" # after each target: a later crash keeps this one
  done
fi
exit $status
