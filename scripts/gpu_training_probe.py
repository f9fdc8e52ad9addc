"""Is training a slip classifier faster on the GPU? Issue 30 runs the AcoMerge family on the GPU and
every gradient method (source models, fine-tuning, distillation, AdaMerging) as CPU jobs; this probe
measures that choice instead of assuming it.

It times one optimiser step of `models/train.py`'s loop (zero_grad, forward, class-weighted CE,
backward, Adam) for SN-S and SN-D at the two batch sizes fleetlab trains with: 32 (source models and
fine-tuning, paper's reference setup) and 200 (one D_Cal, as AdaMerging and distillation see it).
Ways, each a median over `--steps` steps after a warm-up:
- cpu-1: one CPU thread, how an `evaluate` job trains (evaluation/protocol.py pins one thread per job);
- cpu-N: all of torch's CPU threads;
- cuda: eager on the GPU;
- cuda-graph: fleetlab's captured step (models/train.py `_CapturedSteps`: forward, loss, backward and
  Adam with capturable=True in one CUDA graph, replayed per step with the batch's indices uploaded),
  what the source models train with under `--device cuda`.
Prints one JSON object: ms per step per way, and the GPU's best against cpu-1 (a ratio above 1 means
the GPU step is faster). With the GPU, also `training`: fleetlab's own `train_classifier` on the GPU
(what the source models use under `--device cuda`) against one CPU thread, a few epochs on synthetic
rows (2,000, so every epoch ends with a shorter batch and both of its graphs run): seconds each, the
same bits when trained twice on the GPU, and how often the GPU- and CPU-trained models agree. Run on a GPU machine after scripts/gpu_check.sh's shim (gpu_check.sh runs it),
or anywhere with fleetlab installed (`--devices cpu` on a machine without a GPU).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import torch

from fleetlab.data.contracts import N_CLASSES, N_FEATURES
from fleetlab.models import build
from fleetlab.fusion.bench import synthetic_calibration
from fleetlab.models import flatten
from fleetlab.models.train import EXPERT_LR, _CapturedSteps, predict, train_classifier, weighted_ce


def _synchronise(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def _problem(arch: str, batch: int, device: str):
    """A model, its Adam, and one batch of inputs and labels (every class present) on `device`."""
    gen = torch.Generator().manual_seed(0)
    model = build(arch, seed=0).to(device).train()
    x = torch.randn(batch, N_FEATURES, generator=gen).to(device)
    y = (torch.arange(batch) % N_CLASSES).to(device)
    w = torch.ones(N_CLASSES, device=device)
    return model, x, y, w


def _time_eager(arch: str, batch: int, device: str, steps: int) -> float:
    model, x, y, w = _problem(arch, batch, device)
    opt = torch.optim.Adam(model.parameters(), lr=EXPERT_LR)
    times = []
    for i in range(steps + 10):
        _synchronise(device)
        t0 = time.perf_counter()
        opt.zero_grad()
        weighted_ce(model(x), y, w).backward()
        opt.step()
        _synchronise(device)
        if i >= 10:  # warm-up: allocator, kernels' first launch
            times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def _time_cuda_graph(arch: str, batch: int, device: str, steps: int) -> float:
    """fleetlab's own captured step (`_CapturedSteps`, what the source models train with on a GPU): its
    first steps run eagerly, then each step is the batch's indices uploaded and one graph replayed."""
    model, x, y, w = _problem(arch, batch, device)
    engine = _CapturedSteps(model, x, y, w, EXPERT_LR)
    idx = torch.arange(batch)
    times = []
    for i in range(steps + 10):
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        engine.step(idx)
        torch.cuda.synchronize()
        if i >= 10:  # warm-up: the eager steps and the capture
            times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def training_check(arch: str, epochs: int = 3) -> dict:
    """train_classifier on one CPU thread and on the GPU (twice) from the same init and batches."""
    x, y = synthetic_calibration(2000, seed=1)
    x_test, y_test = synthetic_calibration(2000, seed=2)
    out: dict = {"arch": arch, "epochs": epochs, "rows": len(y)}
    models = {}
    for name, device in (("cpu-1", "cpu"), ("cuda", "cuda"), ("cuda_again", "cuda")):
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            _synchronise(device)
            t0 = time.perf_counter()
            models[name] = train_classifier(build(arch, seed=0), x, y, epochs=epochs, seed=3, device=device)
            _synchronise(device)
            out[f"{name}_s"] = round(time.perf_counter() - t0, 3)
        finally:
            torch.set_num_threads(threads)
    flat = {k: flatten(m) for k, m in models.items()}
    out["cuda_same_bits_twice"] = bool(torch.equal(flat["cuda"], flat["cuda_again"]))
    out["max_abs_param_diff_cuda_vs_cpu"] = float((flat["cuda"] - flat["cpu-1"]).abs().max())
    pred = {k: predict(m, x_test) for k, m in models.items()}
    out["test_accuracy_cpu"] = round(float((pred["cpu-1"] == y_test).mean()), 4)
    out["test_accuracy_cuda"] = round(float((pred["cuda"] == y_test).mean()), 4)
    out["prediction_agreement_cuda_vs_cpu"] = round(float((pred["cuda"] == pred["cpu-1"]).mean()), 4)
    return out


def probe(archs: list[str], batches: list[int], devices: list[str], steps: int) -> dict:
    threads = torch.get_num_threads()
    rows = []
    for arch in archs:
        for batch in batches:
            row: dict = {"arch": arch, "batch": batch}
            try:
                torch.set_num_threads(1)
                row["cpu-1_ms"] = round(_time_eager(arch, batch, "cpu", steps), 4)
            finally:
                torch.set_num_threads(threads)
            row[f"cpu-{threads}_ms"] = round(_time_eager(arch, batch, "cpu", steps), 4)
            if "cuda" in devices:
                row["cuda_ms"] = round(_time_eager(arch, batch, "cuda", steps), 4)
                row["cuda-graph_ms"] = round(_time_cuda_graph(arch, batch, "cuda", steps), 4)
                best = min(row["cuda_ms"], row["cuda-graph_ms"])
                row["gpu_best_vs_cpu-1"] = round(row["cpu-1_ms"] / best, 3)
            rows.append(row)
    info = {"torch": torch.__version__, "cpu_threads": threads, "steps_timed": steps}
    out = {"info": info, "step_ms": rows}
    if "cuda" in devices:
        info["gpu"] = torch.cuda.get_device_name(0)
        out["training"] = [training_check(arch) for arch in archs]
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--devices", default="cpu,cuda", help="cpu, or cpu,cuda (default)")
    p.add_argument("--arch", default="sn-s,sn-d", help="comma-separated architectures (default sn-s,sn-d)")
    p.add_argument("--batch", default="32,200", help="comma-separated batch sizes (default 32,200)")
    p.add_argument("--steps", type=int, default=200, help="timed steps per way (default 200)")
    args = p.parse_args()
    devices = args.devices.split(",")
    if set(devices) - {"cpu", "cuda"} or "cpu" not in devices:
        print(f"gpu_training_probe: --devices takes cpu or cpu,cuda, not {args.devices!r}", file=sys.stderr)
        return 2
    if "cuda" in devices and not torch.cuda.is_available():
        print("gpu_training_probe: torch sees no CUDA GPU here (use --devices cpu)", file=sys.stderr)
        return 2
    if args.steps < 1:
        print("gpu_training_probe: --steps must be at least 1", file=sys.stderr)
        return 2
    batches = [int(b) for b in args.batch.split(",")]
    print(json.dumps(probe(args.arch.split(","), batches, devices, args.steps), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
