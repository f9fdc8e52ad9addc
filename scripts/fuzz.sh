#!/usr/bin/env bash
# Run the slipest libFuzzer targets (SLCAN parser, COBS decoder, sample push, model image) for a bounded
# time each, in parallel, and print the executions of each.
#   scripts/fuzz.sh [SECONDS] [BUILD_DIR]     (SECONDS default: $FLEETLAB_FUZZ_SECONDS or 60)
set -euo pipefail
SECONDS_PER_TARGET="${1:-${FLEETLAB_FUZZ_SECONDS:-60}}"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${2:-$ROOT/build/fuzz}"
TARGETS=(fuzz_slcan fuzz_cobs fuzz_push fuzz_image)
PY="${PYTHON:-$(command -v python3 || command -v python)}"

command -v clang >/dev/null || { echo "fuzz.sh: clang not found (scripts/setup.sh installs it)" >&2; exit 2; }
cmake -S "$ROOT" -B "$BUILD" -DCMAKE_C_COMPILER=clang -DSLIPEST_FUZZ=ON -DPython3_EXECUTABLE="$PY" >/dev/null
cmake --build "$BUILD" -j2 --target "${TARGETS[@]}" >/dev/null

LOGS="$BUILD/fuzz-logs"
mkdir -p "$LOGS"
pids=()
for t in "${TARGETS[@]}"; do
  mkdir -p "$BUILD/corpus/$t"
  # seed: a valid image, so that mutations start past the magic, sizes and CRC
  if [ "$t" = fuzz_image ] && [ -z "$(ls -A "$BUILD/corpus/$t")" ]; then
    cp "$ROOT/firmware_c/bundles/example/model.img" "$BUILD/corpus/$t/example.img"
  fi
  # -max_total_time bounds each run; crashes leave a reproducer in $LOGS
  "$BUILD/$t" -max_total_time="$SECONDS_PER_TARGET" -max_len=4096 -print_final_stats=1 \
      -artifact_prefix="$LOGS/$t-" "$BUILD/corpus/$t" >"$LOGS/$t.log" 2>&1 &
  pids+=($!)
done
status=0
for i in "${!TARGETS[@]}"; do
  if ! wait "${pids[$i]}"; then
    echo "FAIL ${TARGETS[$i]}: see $LOGS/${TARGETS[$i]}.log" >&2
    tail -20 "$LOGS/${TARGETS[$i]}.log" >&2
    status=1
  fi
done
for t in "${TARGETS[@]}"; do
  execs=$(grep -E "stat::number_of_executed_units" "$LOGS/$t.log" | awk '{print $2}')
  echo "$t executions=${execs:-0} seconds=$SECONDS_PER_TARGET"
done
exit $status
