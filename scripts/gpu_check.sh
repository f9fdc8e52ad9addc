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
# (generation ms, full run s, 30 runs batched), the CPU figures of the same host beside them,
# the SN-D paper table's wall time on the GPU (30 runs x 2 budgets, every method), and the
# 30-run SN-S table's scores on the GPU against the CPU's (|difference| <= 0.01 per method).
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
echo "== bench fusion --device cuda (SN-S, SN-D)"
"${FL[@]}" bench fusion --device cuda --arch sn-s --full-runs 3 --repeats 50 --json | tee "$OUT_DIR/bench_gpu_sn-s.json"
"${FL[@]}" bench fusion --device cuda --arch sn-d --full-runs 2 --repeats 20 --json | tee "$OUT_DIR/bench_gpu_sn-d.json"
echo "== bench fusion, CPU path on this host (SN-S with --load 1; SN-D one full run)"
"${FL[@]}" bench fusion --arch sn-s --repeats 10 --full-runs 3 --json | tee "$OUT_DIR/bench_cpu_sn-s.json"
"${FL[@]}" bench fusion --arch sn-d --repeats 2 --full-runs 1 --load 0 --json | tee "$OUT_DIR/bench_cpu_sn-d.json"

DATA=${1:-${FLEETLAB_REAL_DATA:-}}
for d in "$DATA" "$ROOT/../shared/data/fleet_to_lab" "$ROOT/data/fleet_to_lab"; do
  if [ -n "$d" ] && ls "$d"/*.csv >/dev/null 2>&1; then DATA=$d; break; else DATA=""; fi
done
if [ -z "$DATA" ]; then
  echo "gpu_check: no Fleet-To-Lab CSVs found (give DATA_DIR or FLEETLAB_REAL_DATA): table steps skipped" >&2
  exit 0
fi
JOBS=$(nproc)
echo "== SN-D paper table on the GPU (30 runs x 2 budgets, every method; others on $JOBS CPU jobs)"
t0=$(date +%s.%N)
"${FL[@]}" evaluate --data "$DATA" --arch sn-d --runs 30 --device cuda --jobs "$JOBS" --no-progress \
  --json "$OUT_DIR/table_sn-d_gpu.json" > "$OUT_DIR/table_sn-d_gpu.md"
t1=$(date +%s.%N)
echo "== SN-S table, 30 runs, AcoMerge family on the GPU and on the CPU"
"${FL[@]}" evaluate --data "$DATA" --runs 30 --methods acomerge,mmas-only --device cuda --jobs "$JOBS" --no-progress \
  --json "$OUT_DIR/table_sn-s_gpu.json" > /dev/null
"${FL[@]}" evaluate --data "$DATA" --runs 30 --methods acomerge,mmas-only --device cpu --jobs "$JOBS" --no-progress \
  --json "$OUT_DIR/table_sn-s_cpu.json" > /dev/null
"$PY" - "$OUT_DIR" "$t0" "$t1" <<'EOF'
import json, sys
out, t0, t1 = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
s = {k: json.load(open(f"{out}/bench_gpu_{k}.json")) for k in ("sn-s", "sn-d")}
c = {k: json.load(open(f"{out}/bench_cpu_{k}.json")) for k in ("sn-s", "sn-d")}
d = json.load(open(f"{out}/table_sn-d_gpu.json"))["timing"]
print("\n== goal figures (issue 30)")
print(f"device: {s['sn-s']['device']}")
print(f"SN-S generation, one run:      {s['sn-s']['generation_ms']:.4f} ms   (goal <= 0.15 ms; "
      f"fitness call alone {s['sn-s']['fitness_ms']:.4f} ms; 30 runs batched: {s['sn-s']['per_run_generation_ms']:.4f} ms per run)")
print(f"SN-D AcoMerge run:             {s['sn-d']['full_run_s']:.3f} s    (goal <= 0.5 s; "
      f"30 runs batched: {s['sn-d']['batched_full_runs_s']:.3f} s for all)")
print(f"SN-D paper table:              {t1 - t0:.1f} s    (goal <= 180 s; MCCV {d['mccv_wall_s']:.1f} s, sources {sum(d['sources_s'].values()):.1f} s)")
print(f"CPU on this host: SN-S run {c['sn-s']['full_run_s']:.3f} s ({c['sn-s']['threads']} threads), "
      f"SN-S generation {c['sn-s']['full_generation_ms']:.3f} ms, SN-D run {c['sn-d']['full_run_s']:.3f} s")
g = json.load(open(f"{out}/table_sn-s_gpu.json"))["results"]
p = json.load(open(f"{out}/table_sn-s_cpu.json"))["results"]
worst = 0.0
for m in g:
    for size in g[m]:
        for metric in ("balanced_accuracy", "macro_f1"):
            a, b = g[m][size][metric]["mean"], p[m][size][metric]["mean"]
            worst = max(worst, abs(a - b))
            print(f"SN-S 30-run table {m:10s} |D_Cal|={size} {metric:17s} GPU {a:.4f} CPU {b:.4f} diff {a - b:+.4f}")
print(f"largest |GPU - CPU| of the table's means: {worst:.4f} ({'within' if worst <= 0.01 else 'OUTSIDE'} +-0.01)")
EOF
echo "gpu_check: done in $(( $(date +%s) - t_start )) s; files in $OUT_DIR"
