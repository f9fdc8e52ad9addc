#!/usr/bin/env bash
# GPU checks of issue 30, in one short run (< 5 min on one H100-class GPU) on a machine WITHOUT
# internet: run from the repository root as `bash scripts/gpu_check.sh [DATA_DIR]`.
#
# Needs python3 with a CUDA torch, numpy, scipy, tqdm, joblib, scikit-learn, matplotlib, onnx,
# markdown (a typical GPU image has them). fleetlab itself is not installed: a shim folder makes
# `import fleetlab` find the repository's sources (pyproject's package-dir mapping, as symlinks).
# The only package fleetlab's fuse/evaluate path needs beyond those is `cma` (Evolutionary Merge);
# if python3 lacks it, put its wheel (cma-4.5.0-py3-none-any.whl, pure Python) into .whl/ and it
# is installed into a private folder, without the network. CAN, serial and Dask packages are not
# imported on this path.
#
# DATA_DIR: the Fleet-To-Lab CSVs (default $FLEETLAB_REAL_DATA, else ../shared/data/fleet_to_lab,
# else data/fleet_to_lab); without them the table step is skipped, saying so.
#
# Prints (and writes to ${OUT:-build/gpu_check}/): bench fusion --device cuda for SN-S and SN-D
# (generation ms compiled and not, full run s, 30 runs batched), the SN-D paper table's wall time
# on the GPU (30 runs x 2 budgets, every method), and the 30-run SN-S table's scores on the GPU
# with `--rng host` (the GPU draws the CPU reference's random numbers, so the difference is float
# rounding only: the criterion, |difference| <= 0.01 per method) against the CPU's, and one training
# step on the CPU against the GPU (scripts/gpu_training_probe.py). Each step says how long it took.
#
# GPU_CHECK_QUICK=1: only the SN-S benchmark and the SN-S GPU-vs-CPU comparison.
# GPU_CHECK_EXTRA=1: also the SN-S table with the default `--rng device` (another random stream:
# information) and the CPU path's bench fusion on this host (SN-S with a core busy, SN-D); they
# take the whole check past 5 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
OUT_DIR=${OUT:-$ROOT/build/gpu_check}
mkdir -p "$OUT_DIR"
PY=${PYTHON:-python3}
SHIM=$(mktemp -d /tmp/fleetlab_shim.XXXXXX)
mkdir -p "$SHIM/fleetlab"
for entry in "$ROOT"/toolchain/*; do ln -s "$entry" "$SHIM/fleetlab/$(basename "$entry")"; done
for pkg in export host_tools dbc canopen_od; do ln -s "$ROOT/$pkg" "$SHIM/fleetlab/$pkg"; done
ORIGINAL_PYTHONPATH=${PYTHONPATH:-}
export PYTHONPATH="$SHIM${ORIGINAL_PYTHONPATH:+:$ORIGINAL_PYTHONPATH}"
if ! "$PY" -c "import cma" 2>/dev/null; then
  wheel=$(ls "$ROOT"/.whl/cma-*.whl 2>/dev/null | head -1 || true)
  if [ -z "$wheel" ]; then
    echo "gpu_check: python3 has no 'cma' and .whl/ holds no cma wheel (pip download cma==4.5.0 -d .whl)" >&2
    exit 2
  fi
  "$PY" -m pip install -q --no-index --no-deps --no-compile --target "$SHIM/site" "$wheel"
  export PYTHONPATH="$SHIM:$SHIM/site${ORIGINAL_PYTHONPATH:+:$ORIGINAL_PYTHONPATH}"
fi
export PYTHONUNBUFFERED=1 OPENBLAS_NUM_THREADS=1
FL=("$PY" -m fleetlab.cli)
"$PY" - <<'EOF'
import sys, torch, fleetlab
print(f"gpu_check: fleetlab from {fleetlab.__path__[0]}")
if not torch.cuda.is_available():
    sys.exit("gpu_check: torch sees no CUDA GPU here")
print(f"gpu_check: torch {torch.__version__}, {torch.cuda.get_device_name(0)}, {torch.get_num_threads()} CPU threads")
EOF
t_start=$(date +%s)
failed=()
step() {  # step NAME SECONDS CMD...: run with a time limit; a failure is reported at the end, not fatal
  local name=$1 limit=$2
  shift 2
  echo "== $name"
  local t0=$SECONDS
  if ! timeout "$limit" "$@"; then
    failed+=("$name")
    echo "gpu_check: step '$name' failed or ran over ${limit} s" >&2
  fi
  echo "== $name: $(( SECONDS - t0 )) s"
}
TO_FILE=(bash -c '"$@" > "$0" && cat "$0"')  # TO_FILE FILE CMD...: the command's stdout into FILE, and shown
DATA=${1:-${FLEETLAB_REAL_DATA:-}}
for d in "$DATA" "$ROOT/../shared/data/fleet_to_lab" "$ROOT/data/fleet_to_lab"; do
  if [ -n "$d" ] && ls "$d"/*.csv >/dev/null 2>&1; then DATA=$d; break; else DATA=""; fi
done
NPROC=$(nproc)
CPU_JOBS=$(( NPROC > 6 ? NPROC - 4 : 2 ))
GPU_SIDE_JOBS=$(( NPROC > 6 ? 3 : 1 ))
SNS=(--runs 30 --methods acomerge --no-progress)
QUICK=${GPU_CHECK_QUICK:-0}
EXTRA=${GPU_CHECK_EXTRA:-0}
cpu_table=""
if [ -n "$DATA" ]; then
  # the CPU side of the SN-S comparison runs on most cores while the GPU benchmarks run
  timeout 280 "${FL[@]}" evaluate --data "$DATA" "${SNS[@]}" --device cpu --jobs "$CPU_JOBS" \
    --json "$OUT_DIR/table_sn-s_cpu.json" > /dev/null 2> "$OUT_DIR/table_sn-s_cpu.err" &
  cpu_table=$!
fi
step "bench fusion --device cuda --arch sn-s" 150 "${TO_FILE[@]}" "$OUT_DIR/bench_gpu_sn-s.json" \
  "${FL[@]}" bench fusion --device cuda --arch sn-s --full-runs 3 --repeats 50 --json
[ "$QUICK" = 1 ] || step "training step, CPU against GPU (is the GPU faster for the gradient methods?)" 60 \
  "${TO_FILE[@]}" "$OUT_DIR/training_probe.json" "$PY" "$ROOT/scripts/gpu_training_probe.py"
[ "$QUICK" = 1 ] || step "bench fusion --device cuda --arch sn-d" 150 "${TO_FILE[@]}" "$OUT_DIR/bench_gpu_sn-d.json" \
  "${FL[@]}" bench fusion --device cuda --arch sn-d --full-runs 2 --repeats 20 --json
if [ -z "$DATA" ]; then
  echo "gpu_check: no Fleet-To-Lab CSVs found (give DATA_DIR or FLEETLAB_REAL_DATA): table steps skipped" >&2
else
  step "SN-S table, 30 runs x 2 budgets, AcoMerge on the GPU, --rng host (the CPU's random numbers)" 150 \
    "${FL[@]}" evaluate --data "$DATA" "${SNS[@]}" --device cuda --rng host --jobs "$GPU_SIDE_JOBS" \
    --json "$OUT_DIR/table_sn-s_gpu_host_rng.json"
  [ "$EXTRA" != 1 ] || step "SN-S table, 30 runs x 2 budgets, AcoMerge on the GPU, --rng device (default)" 150 \
    "${FL[@]}" evaluate --data "$DATA" "${SNS[@]}" --device cuda --jobs "$GPU_SIDE_JOBS" \
    --json "$OUT_DIR/table_sn-s_gpu.json"
  wait "$cpu_table" || { failed+=("SN-S table on the CPU"); tail -3 "$OUT_DIR/table_sn-s_cpu.err" >&2; }
fi
if [ -n "$DATA" ] && [ "$QUICK" != 1 ]; then
  t0=$(date +%s.%N)
  step "SN-D paper table on the GPU (30 runs x 2 budgets, every method; the others on $NPROC CPU jobs)" 240 \
    "${FL[@]}" evaluate --data "$DATA" --arch sn-d --runs 30 --device cuda --jobs "$NPROC" --no-progress \
    --out "$OUT_DIR/table_sn-d_gpu"
  t1=$(date +%s.%N)
  "$PY" -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$t0" "$t1" > "$OUT_DIR/table_sn-d_seconds.txt"
fi
[ "$EXTRA" != 1 ] || step "bench fusion, CPU path on this host (SN-S, with --load 1)" 60 "${TO_FILE[@]}" "$OUT_DIR/bench_cpu_sn-s.json" \
  "${FL[@]}" bench fusion --arch sn-s --repeats 10 --full-runs 3 --json
[ "$EXTRA" != 1 ] || step "bench fusion, CPU path on this host (SN-D, one full run)" 90 "${TO_FILE[@]}" "$OUT_DIR/bench_cpu_sn-d.json" \
  "${FL[@]}" bench fusion --arch sn-d --repeats 2 --full-runs 1 --load 0 --json
"$PY" "$ROOT/scripts/gpu_check_report.py" "$OUT_DIR" | tee "$OUT_DIR/summary.txt"
echo "gpu_check: done in $(( $(date +%s) - t_start )) s; files in $OUT_DIR"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'gpu_check: failed: %s\n' "${failed[@]}" >&2
  exit 1
fi
