"""`fleetlab bench c`: cost of the C estimator on the host and on a Cortex-M4 under QEMU.

Builds (with the real cmake) a host Release build and a Cortex-M4 cross build of
firmware_c for the given bundle, then measures in one run:

* host ns per single-window inference, fixed-point and float (`slipest_bench`),
  against onnxruntime and torch on the same single window (1 thread each);
* Cortex-M4 instructions per inference: the cost image runs under
  `qemu-system-arm -icount shift=0` (one instruction = 1 ns of virtual time) and reads
  SysTick around a calibration loop of known length and around 1,024 inferences
  (Debian's QEMU ships no TCG plugins, so no instruction-counting plugin is used);
* flash/RAM of library + model: sections of the library's objects that survive
  --gc-sections in the linked fixed-point image (from the linker map; startup, libc and
  the test harness excluded), plus the node context and the painted peak stack of the
  frame that closes a window (extraction + fixed-point inference + output frames). The
  cost image links both serial codecs (SLCAN and COBS); `m4_flash_bytes_can_firmware` is
  the same measure on the CAN-native example firmware of docs/integrating_slipest.md.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from ..paths import default_bundle, repo_root

REPO = repo_root()
DEFAULT_BUNDLE = default_bundle()
QEMU = "qemu-system-arm"
TARGETS = {  # cpu -> (toolchain file, QEMU machine)
    "cortex-m4": ("firmware_c/cmake/cortex-m4.cmake", "mps2-an386"),
    "cortex-m3": ("firmware_c/cmake/cortex-m3.cmake", "mps2-an385"),
}


def _run(cmd: list[str], cwd: Path | None = None, timeout: float = 600, merge_stderr: bool = False) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise OSError(f"command failed ({proc.returncode}): {' '.join(map(str, cmd))}\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    # QEMU's semihosting console writes to stderr
    return proc.stdout + proc.stderr if merge_stderr else proc.stdout


def cmake_build(build_dir: Path, bundle: Path, *, cpu: str | None = None, options: dict[str, str] | None = None,
                jobs: int = 2) -> Path:
    """Configure and build firmware_c into build_dir (host, or cross for `cpu`)."""
    build_dir = Path(build_dir)
    args = [
        "cmake", "-S", str(REPO), "-B", str(build_dir), f"-DSLIPEST_BUNDLE={Path(bundle).resolve()}",
        f"-DPython3_EXECUTABLE={sys.executable}", "-DCMAKE_BUILD_TYPE=Release",
    ]
    if cpu is not None:
        args.append(f"-DCMAKE_TOOLCHAIN_FILE={REPO / TARGETS[cpu][0]}")
    for key, value in (options or {}).items():
        args.append(f"-D{key}={value}")
    _run(args)
    _run(["cmake", "--build", str(build_dir), f"-j{jobs}"])
    return build_dir


def qemu_command(cpu: str, image: Path, icount: bool = False) -> list[str]:
    cmd = [QEMU, "-machine", TARGETS[cpu][1], "-cpu", cpu, "-nographic", "-monitor", "none", "-serial", "none",
           "-semihosting-config", "enable=on,target=native"]
    if icount:
        cmd += ["-icount", "shift=0"]
    return cmd + ["-kernel", str(image)]


def parse_kv(text: str) -> dict[str, int]:
    return {k: int(v) for k, v in re.findall(r"^(\w+)=(\d+)\s*$", text, flags=re.M)}


def target_costs(cpu: str, build_dir: Path) -> dict[str, float]:
    """Instructions per inference and node costs from the QEMU cost images."""
    full = parse_kv(_run(qemu_command(cpu, build_dir / "slipest_bench_target.elf", icount=True), timeout=300, merge_stderr=True))
    qonly = parse_kv(_run(qemu_command(cpu, build_dir / "slipest_bench_target_q.elf", icount=True), timeout=300, merge_stderr=True))
    per_tick = full["calib_instructions"] / full["calib_ticks"]
    n = full["inferences"]

    def per_inference(ticks: int) -> float:
        return (ticks - full["empty_ticks"]) * per_tick / n

    return {
        "instructions_per_tick": per_tick,
        "q": per_inference(full["q_ticks"]),
        "f32": per_inference(full["f32_ticks"]),
        "node_instructions_per_sample": qonly["node_99_samples_ticks"] * per_tick / 99,
        "stack_q": qonly["stack_q"],
        "stack_f32": full["stack_f32"],
        "stack_node_window": qonly["stack_node_window"],
        "node_bytes": qonly["node_bytes"],
    }


_MAP_ENTRY = re.compile(r"^ (\.[\w.]+|COMMON)\s*\n?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S+)", re.M)


def library_footprint(map_file: Path, archive: str) -> dict[str, dict[str, int]]:
    """Bytes per object of `archive` in the linked image: flash (text+rodata+data) and static RAM (data+bss)."""
    text = Path(map_file).read_text()
    start = text.find("Linker script and memory map")
    if start < 0:
        raise ValueError(f"{map_file}: no memory map section")
    per_obj: dict[str, dict[str, int]] = {}
    for name, _addr, size, origin in _MAP_ENTRY.findall(text[start:]):
        m = re.match(re.escape(archive) + r"\((.+)\)$", Path(origin).name)
        if not m:
            continue
        size_b = int(size, 16)
        obj = per_obj.setdefault(m.group(1), {"flash": 0, "ram": 0})
        if name.startswith((".text", ".rodata")):
            obj["flash"] += size_b
        elif name.startswith(".data"):
            obj["flash"] += size_b
            obj["ram"] += size_b
        elif name.startswith(".bss") or name == "COMMON":
            obj["ram"] += size_b
    return per_obj


def _time_per_call(fn, n: int) -> float:
    fn()  # warm-up
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter_ns()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter_ns() - t0) / n)
    return best


def python_baselines(bundle: Path, n: int) -> dict[str, Callable[[], object]]:
    """Single-window inference callables for onnxruntime and torch (1 thread each)."""
    import onnxruntime as ort
    import torch

    from fleetlab.export.bundle import load_bundle

    b = load_bundle(bundle)
    with np.load(Path(bundle) / "vectors.npz") as z:
        x = np.ascontiguousarray(z["inputs"][:1], dtype=np.float32)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(str(Path(bundle) / "model.onnx"), opts, providers=["CPUExecutionProvider"])
    name = sess.get_inputs()[0].name

    torch.set_num_threads(1)
    model = b.fparams.to_model()
    xt = torch.from_numpy(x)

    def torch_call():
        with torch.inference_mode():
            return model(xt)

    return {"onnxruntime": lambda: sess.run(None, {name: x}), "torch": torch_call}


def host_timings(host_build: Path, bundle: Path, n: int, rounds: int = 3) -> dict[str, float]:
    """Best-of-rounds ns per inference; C, onnxruntime and torch interleaved so that load
    from other processes hits all of them alike."""
    calls = python_baselines(bundle, n)
    best = {"q": float("inf"), "f32": float("inf"), "onnxruntime": float("inf"), "torch": float("inf")}
    for _ in range(rounds):
        c = json.loads(_run([str(host_build / "slipest_bench"), str(Path(bundle) / "vectors.bin"), "100000"]))
        best["q"] = min(best["q"], c["host_ns_per_inference_q"])
        best["f32"] = min(best["f32"], c["host_ns_per_inference_f32"])
        for key, fn in calls.items():
            best[key] = min(best[key], _time_per_call(fn, n))
    return best


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="export bundle (default: the example bundle)")
    parser.add_argument("--build-dir", type=Path, default=REPO / "build" / "bench",
                        help="where the host and Cortex-M4 builds go (reused when present)")
    parser.add_argument("--iterations", type=int, default=2000,
                        help="onnxruntime/torch inferences per timing round (3 rounds, interleaved with the C bench)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def run(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    bundle = Path(args.bundle)
    if not (bundle / "vectors.bin").is_file():
        raise FileNotFoundError(f"{bundle}: no vectors.bin (not an export bundle?)")
    for tool in ("cmake", "arm-none-eabi-gcc", QEMU):
        if shutil.which(tool) is None:
            raise OSError(f"{tool} not found (scripts/setup.sh installs it)")
    steps = tqdm(total=5, desc="bench c", disable=args.json or not sys.stderr.isatty())
    host = cmake_build(args.build_dir / "host", bundle)
    steps.update()
    m4 = cmake_build(args.build_dir / "cortex-m4", bundle, cpu="cortex-m4")
    steps.update()
    t = host_timings(host, bundle, args.iterations)
    steps.update(2)
    cost = target_costs("cortex-m4", m4)
    lib = library_footprint(m4 / "slipest_bench_target_q.elf.map", "libslipest_q.a")
    # a CAN-attached flight firmware: the integration guide's main loop, no serial codec linked
    can_fw = library_footprint(m4 / "example_minimal_can_loop.elf.map", "libslipest_q.a")
    steps.update()
    steps.close()
    flash = sum(o["flash"] for o in lib.values())
    static_ram = sum(o["ram"] for o in lib.values())
    kernel = lib.get("slipest_infer_q.c.obj", {"flash": 0})["flash"]
    result = {
        "host_ns_per_inference_q": t["q"],
        "host_ns_per_inference_f32": t["f32"],
        "onnxruntime_ns_per_inference": t["onnxruntime"],
        "torch_ns_per_inference": t["torch"],
        "speedup_vs_onnxruntime": t["onnxruntime"] / t["q"],
        "speedup_vs_torch": t["torch"] / t["q"],
        "m4_instructions_per_inference_q": round(cost["q"], 1),
        "m4_instructions_per_inference_f32": round(cost["f32"], 1),
        "m4_flash_bytes": flash,
        # static data + node context + peak stack of the frame that closes a window
        # (feature extraction, fixed-point inference, output frames)
        "m4_ram_bytes": static_ram + cost["node_bytes"] + max(cost["stack_q"], cost["stack_node_window"]),
        "m4_flash_bytes_kernel_and_model": kernel,
        # a firmware uses one link: library + model without the SLCAN codec (COBS link only)
        "m4_flash_bytes_cobs_link_only": flash - lib.get("slipest_slcan.c.obj", {"flash": 0})["flash"],
        # library + model as linked into docs/integrating_slipest.md's CAN main loop (CAN peripheral, no serial link)
        "m4_flash_bytes_can_firmware": sum(o["flash"] for o in can_fw.values()),
        "m4_flash_bytes_by_object": {k: v["flash"] for k, v in sorted(lib.items())},
        "m4_static_ram_bytes": static_ram,
        "m4_node_context_bytes": cost["node_bytes"],
        "m4_stack_bytes_q": cost["stack_q"],
        "m4_stack_bytes_f32": cost["stack_f32"],
        "m4_stack_bytes_node_window": cost["stack_node_window"],
        "m4_instructions_per_sample_node_slcan": round(cost["node_instructions_per_sample"], 1),
        "m4_instructions_per_systick": cost["instructions_per_tick"],
        "targets": {"m4_instructions_q": 3000, "m4_flash_bytes": 6144, "m4_ram_bytes": 1024, "speedup_vs_onnxruntime": 20},
        "bundle": str(bundle),
        "host_cpu_count": os.cpu_count(),
    }
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            if not isinstance(value, dict):
                print(f"{key:42s} {value:.1f}" if isinstance(value, float) else f"{key:42s} {value}")
    return 0
