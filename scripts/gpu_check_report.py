"""The goal figures of issue 30 from the JSON files scripts/gpu_check.sh leaves in OUT_DIR."""

from __future__ import annotations

import json
import sys
from pathlib import Path

SCORE_TOLERANCE = 0.01  # issue 30: a 30-run SN-S table on the GPU within +-0.01 of the CPU's


def load(folder: Path, name: str):
    path = folder / name
    return json.loads(path.read_text()) if path.is_file() and path.stat().st_size else None


def main(folder: Path) -> int:
    s = {k: load(folder, f"bench_gpu_{k}.json") for k in ("sn-s", "sn-d")}
    c = {k: load(folder, f"bench_cpu_{k}.json") for k in ("sn-s", "sn-d")}
    print("\n== goal figures (issue 30)")
    if s["sn-s"]:
        g = s["sn-s"]
        print(f"device: {g['device']}")
        print(f"SN-S generation, one run:  {g['generation_ms']:.4f} ms (goal <= 0.15 ms; fitness call alone "
              f"{g['fitness_ms']:.4f} ms; one more generation {g.get('generation_ms_steady', float('nan')):.4f} ms; "
              f"eager {g['generation_ms_eager']:.4f} ms; uncompiled {g.get('generation_ms_uncompiled', float('nan')):.4f} "
              f"ms; compiling took {g.get('compile_s', float('nan')):.1f} s once; "
              f"graph run == eager run: {g.get('cuda_graph_same_search')}; "
              f"{g['batch_runs']} runs batched: {g['batched_generation_ms']:.4f} ms per "
              f"generation, {g['per_run_generation_ms']:.4f} ms per run)")
    if s["sn-d"]:
        g = s["sn-d"]
        print(f"SN-D AcoMerge run:         {g['full_run_s']:.3f} s (goal <= 0.5 s; generation {g['generation_ms']:.3f} ms, "
              f"uncompiled {g.get('generation_ms_uncompiled', float('nan')):.3f} ms; "
              f"{g['batch_runs']} runs batched: {g['batched_full_runs_s']:.3f} s for all)")
    table = load(folder, "table_sn-d_gpu/results.json")
    if table:
        seconds = (folder / "table_sn-d_seconds.txt").read_text().strip()
        t = table["timing"]
        src = t["sources_s"]  # the experts' and the joint model's jobs run side by side; *_cpu: their CPU time
        sources = max(src.get("experts", 0.0), src.get("joint", 0.0)) + src.get("rebasin", 0.0)
        print(f"SN-D paper table:          {seconds} s (goal <= 180 s; sources {sources:.1f} s, "
              f"MCCV {t['mccv_wall_s']:.1f} s, {len(table['results'])} methods, on {t.get('device')})")
        print("  mean seconds per run: " + ", ".join(f"{m} {v:.2f}" for m, v in t["method_mean_s"].items()))
    if c["sn-s"]:
        b = c["sn-s"].get("busy", {})
        print(f"CPU on this host: SN-S run {c['sn-s']['full_run_s']:.3f} s ({c['sn-s']['threads']} threads), generation "
              f"{c['sn-s']['full_generation_ms']:.3f} ms; as is / with a core busy {b.get('run_s_idle')} / "
              f"{b.get('run_s_loaded')} s")
    if c["sn-d"]:
        print(f"CPU on this host: SN-D run {c['sn-d']['full_run_s']:.3f} s ({c['sn-d']['threads']} threads), generation "
              f"{c['sn-d']['full_generation_ms']:.3f} ms")
    probe = load(folder, "training_probe.json")
    if probe:
        print("one training step (zero_grad, forward, CE, backward, Adam), ms: cpu-1 = one thread, as an evaluate "
              "job trains; the GPU's best of eager and CUDA graph against it")
        for r in probe["step_ms"]:
            ways = ", ".join(f"{k[:-3]} {v:.3f}" for k, v in r.items() if k.endswith("_ms"))
            print(f"  {r['arch']} batch {r['batch']:3d}: {ways}; GPU best vs cpu-1 x{r.get('gpu_best_vs_cpu-1')}")
        for t in probe.get("training", []):
            print(f"  train_classifier {t['arch']}, {t['epochs']} epochs of {t['rows']} rows: cpu-1 {t['cpu-1_s']} s, "
                  f"GPU {t['cuda_s']} s / {t['cuda_again_s']} s (same bits twice: {t['cuda_same_bits_twice']}); "
                  f"test accuracy CPU {t['test_accuracy_cpu']} GPU {t['test_accuracy_cuda']}, predictions agree "
                  f"{t['prediction_agreement_cuda_vs_cpu']}")
    cpu = load(folder, "table_sn-s_cpu.json")
    for name, what in (("table_sn-s_gpu_host_rng.json", "--rng host, the CPU's random numbers: the criterion"),
                       ("table_sn-s_gpu.json", "--rng device, another random stream: information only")):
        gpu = load(folder, name)
        if gpu and cpu:
            compare(gpu, cpu, what)
    return 0


def compare(gpu: dict, cpu: dict, what: str) -> None:
    """Each mean score of the GPU's SN-S table against the CPU's, and the largest difference."""
    print(f"SN-S 30-run table, GPU ({what}) vs CPU:")
    worst = 0.0
    for m in gpu["results"]:
        for size in gpu["results"][m]:
            for metric in ("balanced_accuracy", "macro_f1"):
                a, b = gpu["results"][m][size][metric]["mean"], cpu["results"][m][size][metric]["mean"]
                worst = max(worst, abs(a - b))
                print(f"  {m} |D_Cal|={size} {metric:17s} GPU {a:.4f} CPU {b:.4f} diff {a - b:+.4f}")
    verdict = "within" if worst <= SCORE_TOLERANCE else "OUTSIDE"
    print(f"  largest |GPU - CPU| of the table's means: {worst:.4f} ({verdict} +-{SCORE_TOLERANCE})")


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
