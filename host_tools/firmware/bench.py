"""`fleetlab bench c`: cost of the C estimator on the host and on CPU targets under QEMU.

`--list-targets` lists the CPU targets found by `targets.discover()`. `--target NAME|all` (default:
the reference target, marked SLIPEST_TARGET_REFERENCE) builds (with the real cmake) a host Release build and a cross build
per target for the given bundle, then measures in one run:

* host ns per single-window inference, fixed-point and float (`slipest_bench`),
  against onnxruntime and torch on the same single window (1 thread each);
* instructions per inference on targets with a SysTick counter (Cortex-M): the cost image runs under
  `qemu-system-arm -icount shift=0` (one instruction = 1 ns of virtual time) and reads
  SysTick around a calibration loop of known length and around 1,024 inferences
  (Debian's QEMU ships no TCG plugins, so no instruction-counting plugin is used);
* flash/RAM of library + model: sections of the library's objects that survive
  --gc-sections in the linked fixed-point image (from the linker map; startup, libc and
  the test harness excluded), plus the node context and the painted peak stack of the
  frame that closes a window (extraction + fixed-point inference + output frames). The
  cost image links both serial codecs (SLCAN and COBS); `m4_flash_bytes_can_firmware` is
  the same measure on the CAN-native example firmware of docs/integrating_slipest.md.
  `m4_*_model_slots` are what A/B model slots on NVM add (docs/model_slots.md): the flash of the
  store, SHA-256, image-reader and model-check objects linked into the store test image, and the RAM of its
  `slipest_store_t` (its symbol size in that image); `*_can_node_with_slots` add them to the CAN node.

The reference target's figures keep their `m4_*` keys; every target's figures are under `cpu_targets`.
Where the guest has no counter QEMU drives (user-mode PowerPC, bare-metal SPARC), the cost image is run
under QEMU's one-instruction-per-block exec trace and the instructions between marks are counted; a
target with no counter at all (link-only) reports null with the reason, never an estimate.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from . import targets as target_registry
from .build import cmake_build, run, run_image, run_record
from ...errors import need
from ...paths import build_root, default_bundle, repo_root
from .targets import Target

_run = run  # the host bench binary is run through the same helper


def parse_kv(text: str) -> dict[str, int]:
    return {k: int(v) for k, v in re.findall(r"^(\w+)=(\d+)\s*$", text, flags=re.M)}


MARK = "] slipest_count_mark"


def instructions_between_marks(trace: Path) -> list[int]:
    """Executed instructions between consecutive (start, end) calls of slipest_count_mark in a QEMU
    exec trace taken with -singlestep -d exec,nochain: every "Trace" line is one guest instruction."""
    entries, n, in_mark = [], 0, False
    with open(trace, errors="replace") as fh:
        for line in fh:
            if not line.startswith("Trace "):
                continue
            here = MARK in line
            if here and not in_mark:
                entries.append(n)
            in_mark = here
            n += 1
    if len(entries) % 2:
        raise ValueError(f"{trace}: odd number of count marks ({len(entries)})")
    return [entries[k + 1] - entries[k] for k in range(0, len(entries), 2)]


def _counted_kv(t: Target, build_dir: Path, image: str) -> dict[str, int]:
    """key=value output of a cost image; on exec-trace targets the *_ticks placeholders (all but the
    calibration) are replaced, in output order, by the instructions counted in the trace."""
    if t.counter != "trace":
        return parse_kv(run_image(build_dir, image, icount=True))
    with tempfile.TemporaryDirectory(dir=build_dir) as d:
        log = Path(d) / "exec.log"
        kv = parse_kv(run_image(build_dir, image, icount=True, trace=log, timeout=900))
        phases = instructions_between_marks(log)
    keys = [k for k in kv if k.endswith("_ticks") and k != "calib_ticks"]
    if len(keys) != len(phases):
        raise ValueError(f"{image}: {len(keys)} counted phases printed, {len(phases)} marked in the trace")
    kv.update(zip(keys, phases))
    return kv


def target_costs(target: Target | str, build_dir: Path) -> dict[str, float | None]:
    """Instructions per inference and node costs from the QEMU cost images (SysTick or minstret under -icount);
    on an integer-only target there is no float image and the float figures are None."""
    t = target_registry.get(target) if isinstance(target, str) else target
    qonly = _counted_kv(t, build_dir, "slipest_bench_target_q.elf")
    full = None if t.integer_only else _counted_kv(t, build_dir, "slipest_bench_target.elf")
    ref = full or qonly
    per_tick = ref["calib_instructions"] / ref["calib_ticks"]
    n = ref["inferences"]

    def per_inference(ticks: int) -> float:
        return (ticks - ref["empty_ticks"]) * per_tick / n

    return {
        "instructions_per_tick": per_tick,
        "q": per_inference(ref["q_ticks"]),
        "f32": per_inference(full["f32_ticks"]) if full else None,
        "node_instructions_per_sample": qonly["node_99_samples_ticks"] * per_tick / 99,
        "stack_q": qonly["stack_q"],
        "stack_f32": full["stack_f32"] if full else None,
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


SERIAL_LINK_OBJECTS = ("slipest_slcan", "slipest_cobs", "slipest_crc")


def _by_source(footprint: dict[str, dict[str, int]]) -> dict[str, dict[str, int]]:
    """Objects keyed by source stem: CMake names them x.c.obj on bare metal and x.c.o on Linux."""
    return {re.sub(r"\.c\.o(bj)?$", "", k): v for k, v in footprint.items()}


# the fixed-point kernel plus the model as data: the bundle's const structs and its hash
KERNEL_AND_MODEL_OBJECTS = ("slipest_infer_q", "slipest_bundle_q", "slipest_model_hash")


def target_figures(t: Target, build_dir: Path) -> dict:
    """One row of the targets table: instruction counts (where counted), flash and peak stack.

    Flash is counted the same way on every target, from linker maps (library objects kept by
    --gc-sections): kernel + model in the fixed-point cost image; the CAN node (node, generated CAN
    codec, extractor, kernel + model, status) in the node-frames image, without the serial-link
    codecs (SLCAN, COBS, CRC) that image also links."""
    bench_map = build_dir / "slipest_bench_target_q.elf.map"
    kernel_map = bench_map if bench_map.is_file() else build_dir / "slipest_test_q.elf.map"
    lib = _by_source(library_footprint(kernel_map, "libslipest_q.a"))
    node = _by_source(library_footprint(build_dir / "slipest_node_frames.elf.map", "libslipest_q.a"))
    row: dict = {
        "description": t.description, "emulator": t.emulator, "endian": t.endian, "fpu": t.fpu,
        "integer_only": t.integer_only,
        "flash_bytes_kernel_and_model": sum(lib.get(k, {"flash": 0})["flash"] for k in KERNEL_AND_MODEL_OBJECTS),
        "flash_bytes_can_node": sum(o["flash"] for k, o in node.items() if k not in SERIAL_LINK_OBJECTS),
        "flash_bytes_by_object_can_node": {k: o["flash"] for k, o in sorted(node.items())},
    }
    if t.counter != "none":
        cost = target_costs(t, build_dir)
        row.update({
            "instructions_per_inference_q": round(cost["q"], 1),
            "instructions_per_inference_f32": None if cost["f32"] is None else round(cost["f32"], 1),
            "instructions_per_sample_node_slcan": round(cost["node_instructions_per_sample"], 1),
            "stack_bytes_q": cost["stack_q"], "stack_bytes_f32": cost["stack_f32"],
            "stack_bytes_node_window": cost["stack_node_window"],
            "counted_by": {"systick": "SysTick under qemu -icount shift=0",
                           "instret": "minstret under qemu -icount shift=0",
                           "trace": "qemu exec trace, one instruction per block"}[t.counter],
        })
    else:
        row.update({k: None for k in ("instructions_per_inference_q", "instructions_per_inference_f32",
                                      "instructions_per_sample_node_slcan", "stack_bytes_q", "stack_bytes_f32",
                                      "stack_bytes_node_window")})
        row["counted_by"] = (f"not counted: {t.emulator} has no instruction counter this bench reads "
                             "(-icount is system-mode only; Debian's QEMU ships no TCG plugins)")
    return row


# the CANopen node with two model slots (firmware_c/target/co_node_target.c), by part
CANOPEN_PARTS = {
    "canopen": ("slipest_co", "slipest_co_sdo", "slipest_co_od_access", "slipest_co_od"),
    "store": ("slipest_store", "slipest_sha256", "slipest_image", "slipest_model"),
}
CANOPEN_GOALS = {"ram_bytes": 4096, "flash_bytes": 12288}  # issue 20: the whole CANopen node on the M4


def _canopen_image_figures(build_dir: Path, image: str) -> dict:
    out = run_image(build_dir, image)
    if "PASS" not in out:
        raise OSError(f"{build_dir}/{image} did not pass:\n{out[-1000:]}")
    kv = parse_kv(out)
    lib = _by_source(library_footprint(build_dir / f"{image}.map", "libslipest_q.a"))
    flash = sum(o["flash"] for o in lib.values())
    static_ram = sum(o["ram"] for o in lib.values())
    stack = max(kv["stack_co_window"], kv["stack_co_upload_end"], kv["stack_co_activate"])
    by_part = {part: sum(lib.get(k, {"flash": 0})["flash"] for k in objs) for part, objs in CANOPEN_PARTS.items()}
    by_part["estimator and kernel"] = flash - sum(by_part.values())
    return {
        "flash_bytes": flash,
        "ram_bytes": static_ram + kv["co_node_bytes"] + kv["store_bytes"] + stack,
        "flash_bytes_by_part": by_part,
        "ram_parts": {"static": static_ram, "node_context": kv["co_node_bytes"], "store": kv["store_bytes"],
                      "peak_stack": stack},
        "image_bytes": kv["image_bytes"],
    }


def canopen_node_figures(build_dir: Path) -> dict:
    """RAM and flash of the CANopen node with two model slots, as linked and run in its target images
    (launch model provisioned into slot A, upload by SDO block download, activation, one window): flash =
    library objects kept in the image (node, CANopen, store, kernel; the flight image links no built-in
    model, its models are data in the slots); RAM = their static data + the node context + the
    store (one model in RAM, one sector buffer) + the peak stack of the heaviest call. The NVM area is
    the integrator's flash and is not counted. The main figures are the keyless node's; "with_auth" is
    the same node built to authenticate images (HMAC-SHA256 linked, signed images only)."""
    fig = _canopen_image_figures(build_dir, "slipest_co_node.elf")
    fig["with_auth"] = _canopen_image_figures(build_dir, "slipest_co_node_auth.elf")
    fig["goals"] = CANOPEN_GOALS
    return fig


def _goal_line(co_node: dict) -> str:
    """The CANopen node's figures against issue 20's goals, keyless and authenticating."""
    goals = co_node["goals"]

    def verdict(fig: dict) -> str:
        ok = fig["ram_bytes"] <= goals["ram_bytes"] and fig["flash_bytes"] <= goals["flash_bytes"]
        return f"RAM {fig['ram_bytes']}/{goals['ram_bytes']}, flash {fig['flash_bytes']}/{goals['flash_bytes']} " \
               f"({'met' if ok else 'over'})"

    return f"keyless {verdict(co_node)}; with HMAC {verdict(co_node['with_auth'])}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bundle", type=Path, default=None, help="export bundle (default: the example bundle)")
    parser.add_argument("--build-dir", type=Path, default=None,
                        help="where the host and target builds go, reused when present (default: bench/ under "
                             "the build root: build/ in a clone, else the user's cache folder)")
    parser.add_argument("--iterations", type=int, default=2000,
                        help="onnxruntime/torch inferences per timing round (3 rounds, interleaved with the C bench)")
    parser.add_argument("--target", default=None,
                        help="CPU target (a file under firmware_c/cmake/, see --list-targets) or 'all' "
                             "(default: the reference target, whose figures are the m4_* keys)")
    parser.add_argument("--list-targets", action="store_true", help="list the CPU targets and exit")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def _list_targets(as_json: bool) -> int:
    found = target_registry.discover()
    if as_json:
        print(json.dumps({name: t.as_dict() for name, t in found.items()}))
        return 0
    for name, t in found.items():
        flags = ", ".join([t.endian + "-endian", "FPU" if t.fpu else "no FPU"] + (["integer-only"] if t.integer_only else []))
        tree = repo_root()
        print(f"{name:14s} {t.description} [{flags}] -- {t.emulator}  ({t.file.relative_to(tree) if t.file.is_relative_to(tree) else t.file})")
    return 0


def run(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    if args.list_targets:
        return _list_targets(args.json)
    found = target_registry.discover()
    ref = target_registry.reference().name
    names = [n for n, t in found.items() if t.runs] if args.target == "all" else [target_registry.get(args.target or ref).name]
    if not found[names[-1]].runs:
        raise ValueError(f"target {names[-1]} is link-only (no emulator): nothing to measure")
    if ref not in names:
        names.insert(0, ref)  # the m4_* keys (and the figures) are always measured
    bundle = Path(args.bundle or default_bundle())
    if not (bundle / "vectors.bin").is_file():
        raise FileNotFoundError(f"{bundle}: no vectors.bin (not an export bundle?)")
    args.build_dir = Path(args.build_dir or build_root() / "bench")
    need("cmake", "fleetlab bench c")
    for name in names:
        found[name].need_tools(f"fleetlab bench c --target {name}")
    steps = tqdm(total=2 + 2 * len(names), desc="bench c", disable=args.json or not sys.stderr.isatty())
    host = cmake_build(args.build_dir / "host", bundle)
    steps.update()
    builds = {}
    for name in names:
        builds[name] = cmake_build(args.build_dir / name, bundle, target=found[name])
        steps.update()
    t = host_timings(host, bundle, args.iterations)
    steps.update()
    rows = {}
    for name in names:
        rows[name] = target_figures(found[name], builds[name])
        steps.update()
    m4 = builds[ref]
    cost = target_costs(ref, m4)
    lib = library_footprint(m4 / "slipest_bench_target_q.elf.map", "libslipest_q.a")
    # a CAN-attached flight firmware: the integration guide's main loop, no serial codec linked
    can_fw = library_footprint(m4 / "example_minimal_can_loop.elf.map", "libslipest_q.a")
    slots = model_slots_footprint(m4)
    co_node = canopen_node_figures(m4)
    steps.close()
    flash = sum(o["flash"] for o in lib.values())
    static_ram = sum(o["ram"] for o in lib.values())
    kernel = sum(o["flash"] for k, o in _by_source(lib).items() if k in KERNEL_AND_MODEL_OBJECTS)
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
        # A/B model slots on NVM (docs/model_slots.md): store + SHA-256 + image reader, and slipest_store_t
        "m4_flash_bytes_model_slots": slots["flash"],
        "m4_ram_bytes_model_slots": slots["ram"],
        "m4_flash_bytes_can_node_with_slots": sum(o["flash"] for k, o in can_fw.items() if k not in STORE_OBJECTS)
        + slots["flash"],
        "m4_static_ram_bytes": static_ram,
        "m4_node_context_bytes": cost["node_bytes"],
        "m4_stack_bytes_q": cost["stack_q"],
        "m4_stack_bytes_f32": cost["stack_f32"],
        "m4_stack_bytes_node_window": cost["stack_node_window"],
        "m4_instructions_per_sample_node_slcan": round(cost["node_instructions_per_sample"], 1),
        "m4_instructions_per_systick": cost["instructions_per_tick"],
        "m4_label": found[ref].label,
        # the CANopen node with two model slots (issue 20 goal: <= 4 KB RAM, <= 12 KB flash)
        "m4_canopen_node_ram_bytes": co_node["ram_bytes"],
        "m4_canopen_node_flash_bytes": co_node["flash_bytes"],
        "m4_canopen_node_auth_ram_bytes": co_node["with_auth"]["ram_bytes"],
        "m4_canopen_node_auth_flash_bytes": co_node["with_auth"]["flash_bytes"],
        "m4_canopen_node": co_node,
        "cpu_targets": rows,
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
        parts = ", ".join(f"{k} {v}" for k, v in co_node["flash_bytes_by_part"].items())
        print(f"{'m4_canopen_node_flash_by_part':42s} {parts}")
        print(f"{'m4_canopen_node_ram_parts':42s} " + ", ".join(f"{k} {v}" for k, v in co_node["ram_parts"].items()))
        print(f"{'m4_canopen_node_goals':42s} {_goal_line(co_node)}")
        print()
        print(format_table(rows))
    return 0


STORE_OBJECTS = ("slipest_store.c.obj", "slipest_sha256.c.obj", "slipest_image.c.obj", "slipest_model.c.obj")


def model_slots_footprint(build_dir: Path) -> dict[str, int]:
    """Flash of the model-store objects and RAM of the store state, from the store test image
    (firmware_c/target/store_target.c) of a cross build."""
    image = Path(build_dir) / "slipest_store_target.elf"
    objs = library_footprint(Path(f"{image}.map"), "libslipest_q.a")
    nm = run_record(build_dir)["nm"]
    out = subprocess.run([nm, "-S", str(image)], capture_output=True, text=True, check=True).stdout
    m = re.search(r"^[0-9a-f]+ ([0-9a-f]+) [bB] store$", out, flags=re.M)
    if m is None:
        raise ValueError(f"{image}: no 'store' symbol (slipest_store_t) in the symbol table")
    return {"flash": sum(o["flash"] for k, o in objs.items() if k in STORE_OBJECTS), "ram": int(m.group(1), 16),
            "objects": {k: v["flash"] for k, v in objs.items() if k in STORE_OBJECTS}}


def _cell(v) -> str:
    if v is None:
        return "n/a"
    return f"{v:,.0f}" if isinstance(v, (int, float)) else str(v)


def format_table(rows: dict[str, dict]) -> str:
    """The targets table of docs/integrating_slipest.md (Markdown)."""
    head = ("| target | emulator | instr./q inference | instr./float inference | instr./sample (node) "
            "| flash kernel+model (B) | flash CAN node (B) | peak stack q (B) |")
    lines = [head, "|" + "---|" * 8]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['emulator']} | {_cell(r['instructions_per_inference_q'])} "
                     f"| {_cell(r['instructions_per_inference_f32'])} | {_cell(r['instructions_per_sample_node_slcan'])} "
                     f"| {_cell(r['flash_bytes_kernel_and_model'])} | {_cell(r['flash_bytes_can_node'])} "
                     f"| {_cell(r['stack_bytes_q'])} |")
    return "\n".join(lines)
