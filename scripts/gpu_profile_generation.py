"""Where an SN-S AcoMerge generation spends its GPU time: kernels per generation and the
heaviest kernels, from torch's profiler over an eager lockstep run (the kernels a replayed
graph runs are the same). Run on a GPU machine with fleetlab installed, or after
scripts/gpu_check.sh with its shim: `PYTHONPATH=$S:$S/site python3 scripts/gpu_profile_generation.py`
where S is the /tmp/fleetlab_shim.* folder it left."""

from __future__ import annotations

import argparse
import sys

import torch
from torch.profiler import ProfilerActivity, profile

from fleetlab.fusion.acomerge import AcoMergeConfig, checked_inputs
from fleetlab.fusion.bench import synthetic_calibration
from fleetlab.fusion.lockstep import StackedFitness, search_lockstep
from fleetlab.models import build, flatten


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--arch", default="sn-s", choices=("sn-s", "sn-d"))
    p.add_argument("--generations", type=int, default=24)
    p.add_argument("--compiled", action="store_true", help="the compiled steps (lockstep.generation_steps)")
    args = p.parse_args()
    if not torch.cuda.is_available():
        print("gpu_profile_generation: torch sees no CUDA GPU here", file=sys.stderr)
        return 2
    x, y = synthetic_calibration(200, seed=0)
    experts = torch.stack([flatten(build(args.arch, seed=k)) for k in range(3)])
    cfg = AcoMergeConfig(generations=args.generations, device="cuda")
    buffer = checked_inputs(experts, args.arch, cfg, 0, None)[2]
    fitness = StackedFitness(args.arch, [(x, y)], "cuda")
    run = lambda: search_lockstep([experts], [buffer], fitness, cfg, [0], "cuda", cuda_graph=False,  # noqa: E731
                                compiled=args.compiled)
    run()
    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        run()
        torch.cuda.synchronize()
    kernels = [e for e in prof.events() if e.device_type == torch.autograd.DeviceType.CUDA]
    total_us = sum(e.device_time for e in kernels)
    print(f"{args.arch}{' compiled' if args.compiled else ''}: {len(kernels) / args.generations:.0f} GPU kernels per generation, "
          f"{total_us / args.generations / 1e3:.4f} ms of kernel time per generation (set-up included)")
    by_name: dict[str, list[float]] = {}
    for e in kernels:
        by_name.setdefault(e.name, []).append(e.device_time)
    for name, times in sorted(by_name.items(), key=lambda kv: -sum(kv[1]))[:15]:
        print(f"  {sum(times) / args.generations:8.2f} us/gen  {len(times) / args.generations:5.1f}x  {name[:90]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
