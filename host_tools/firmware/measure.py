"""Measurements behind `fleetlab bench c`: what the cost images print, what the linker and `nm`
recorded, and how fast the host runs one inference. Numbers only; figures.py turns them into the
reported figures.

* key=value lines of a QEMU cost image (`parse_kv`), and on exec-trace targets the instructions
  between the image's count marks (`instructions_between_marks`);
* instructions per inference, per sample and the painted stacks of one target (`target_costs`);
* bytes per library object in a linked image, from its linker map (`library_footprint`), and the
  model store's flash and RAM (`model_slots_footprint`), where the build has the bundle's store image
  (`bundle_images`);
* host ns per single-window inference of the C bench, onnxruntime and torch (`host_timings`).
"""

from __future__ import annotations

import json
import re
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from . import targets as target_registry
from .build import run, run_image, run_record
from .targets import Target
from fleetlab.errors import InputError

MARK = "] slipest_count_mark"
_MAP_ENTRY = re.compile(r"^ (\.[\w.]+|COMMON)\s*\n?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S+)", re.M)
# the model store's objects (docs/model_slots.md): store, SHA-256, image reader (its stream, the format-1 visitor, the
# whole-buffer readers), model check; the format-2 visitor is linked only in a build with the layer-table reader
STORE_OBJECTS = ("slipest_store.c.obj", "slipest_sha256.c.obj", "slipest_image_stream.c.obj", "slipest_image_v1.c.obj",
                 "slipest_image_buffer.c.obj", "slipest_image_table.c.obj", "slipest_model.c.obj")


def parse_kv(text: str) -> dict[str, int]:
    return {k: int(v) for k, v in re.findall(r"^(\w+)=(\d+)\s*$", text, flags=re.M)}


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
        raise InputError(f"{trace}: odd number of count marks ({len(entries)})")
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
        raise InputError(f"{image}: {len(keys)} counted phases printed, {len(phases)} marked in the trace")
    kv.update(zip(keys, phases))
    return kv


def target_costs(target: Target | str, build_dir: Path) -> dict[str, float | None]:
    """Instructions per inference and node costs from the QEMU cost images (SysTick or minstret under -icount);
    on an integer-only target there is no float image and the float figures are None."""
    t = target_registry.get(target) if isinstance(target, str) else target
    qonly = _counted_kv(t, build_dir, "slipest_bench_target_q.elf")
    full = None if t.integer_only else _counted_kv(t, build_dir, "slipest_bench_target.elf")
    return costs_from_counts(t.name, qonly, full)


def costs_from_counts(name: str, qonly: dict, full: dict | None) -> dict[str, float | None]:
    """target_costs from the key=value counts of the two cost images (full is None on an integer-only target)."""
    ref = full or qonly
    per_tick = ref["calib_instructions"] / ref["calib_ticks"]
    n = ref["inferences"]  # the empty loop's iterations

    def per_inference(phase: str) -> float:
        # a slow model times fewer calls than the empty loop ran, so that its phase does not wrap the
        # counter (bench_target.c calls_that_fit): the loop overhead is taken per call
        calls = ref[f"{phase}_calls"]
        if calls < 1:
            raise InputError(f"{name}: one {phase} inference takes more than half the cycle counter's range; "
                             "its cost cannot be measured on this target")
        return (ref[f"{phase}_ticks"] - ref["empty_ticks"] * calls / n) * per_tick / calls

    return {
        "instructions_per_tick": per_tick,
        "q": per_inference("q"),
        "f32": per_inference("f32") if full else None,
        "node_instructions_per_sample": qonly["node_99_samples_ticks"] * per_tick / 99,
        "stack_q": qonly["stack_q"],
        "stack_f32": full["stack_f32"] if full else None,
        "stack_node_window": qonly["stack_node_window"],
        "node_bytes": qonly["node_bytes"],
    }


def _map_entries(map_file: Path) -> list[tuple[str, str, str, str]]:
    """(section, address, size, input file) of every input section a linker map places."""
    text = Path(map_file).read_text()
    start = text.find("Linker script and memory map")
    if start < 0:
        raise InputError(f"{map_file}: no memory map section")
    return _MAP_ENTRY.findall(text[start:])


def library_footprint(map_file: Path, archive: str) -> dict[str, dict[str, int]]:
    """Bytes per object of `archive` in the linked image: flash (text+rodata+data) and static RAM (data+bss)."""
    per_obj: dict[str, dict[str, int]] = {}
    for name, _addr, size, origin in _map_entries(map_file):
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


_LTO_OBJECT = re.compile(r"\.ltrans\d*\.ltrans\.o$")
_LINE_ROW = re.compile(r"^(\S+)\s+(\d+|-)\s+0x([0-9a-f]+)", re.M)


def lto_footprint(map_file: Path, image: Path, archive: Path, tools: dict[str, str]) -> dict[str, dict[str, int]]:
    """Bytes per library source in an image whose library was optimised at link time (-flto, built with -g), keyed
    like `library_footprint` ("x.c.obj"). The linker map names only GCC's link-time partitions (*.ltrans.o): their
    sections are the total. Code is split by the debug line table (an inlined function's bytes count with the file
    that defines it; a header's inline helpers with the .c file they were inlined into, else with the function's
    own file); constants by the file that defines their symbol (`nm` of `archive`, the same sources built without
    -flto). What neither covers (alignment padding) is "(link-time partition)". `tools`: the build's nm and objdump."""
    if not tools.get("objdump") or not tools.get("nm"):
        raise InputError(f"{image}: the build recorded no nm or objdump of its toolchain (configure it again)")
    ranges, consts, flash, ram = [], [], 0, 0  # the partitions' code, and their constants and data
    for name, addr, size, origin in _map_entries(map_file):
        if not _LTO_OBJECT.search(origin):
            continue
        size_b, addr_i = int(size, 16), int(addr, 16)
        ram += size_b if name.startswith((".data", ".bss")) or name == "COMMON" else 0
        if name.startswith((".text", ".rodata", ".data")):  # not the debug sections (address 0)
            flash += size_b
            (ranges if name.startswith(".text") else consts).append((addr_i, addr_i + size_b))
    inside = lambda a, rs=ranges: any(lo <= a < hi for lo, hi in rs)  # noqa: E731
    home: dict[str, str] = {}
    for line in subprocess.run([tools["nm"], "-A", str(archive)], capture_output=True, text=True,
                               check=True).stdout.splitlines():
        m = re.match(r".*:(\S+\.o(?:bj)?):\s*(?:[0-9a-fA-F]+)?\s+([tTrRdD])\s+(\S+)$", line)
        if m:
            home.setdefault(m.group(3), m.group(1))
    symbols = []  # (start, size, name without GCC's clone suffix) of the image
    for line in subprocess.run([tools["nm"], "-S", str(image)], capture_output=True, text=True,
                               check=True).stdout.splitlines():
        f = line.split()
        if len(f) == 4:
            symbols.append((int(f[0], 16), int(f[1], 16), f[3].split(".")[0]))
    per_obj: dict[str, dict[str, int]] = {}

    def add(source: str | None, n: int) -> None:
        per_obj.setdefault(source or "(link-time partition)", {"flash": 0, "ram": 0})["flash"] += n

    def owner(a: int) -> str | None:
        return next((home[nm_] for lo, n, nm_ in symbols if lo <= a < lo + n and nm_ in home), None)

    lines = subprocess.run([tools["objdump"], "--dwarf=decodedline", str(image)], capture_output=True, text=True,
                           check=True).stdout
    prev = None  # (file, address, the .c file of this sequence so far)
    for f, ln, a in _LINE_ROW.findall(lines):
        addr = int(a, 16)
        if prev is not None and inside(prev[1]):
            src = prev[0] if prev[0].endswith(".c") else prev[2]
            add(f"{src}.obj" if src else owner(prev[1]), addr - prev[1])
        prev = None if ln == "-" else (f, addr, f if f.endswith(".c") else (prev[2] if prev else None))
    for lo, n, nm_ in symbols:
        if nm_ in home and inside(lo, consts):
            add(home[nm_], n)
    covered = sum(v["flash"] for v in per_obj.values())
    if covered > flash:
        raise InputError(f"{image}: {covered} B attributed, more than its link-time partitions' {flash} B")
    add(None, flash - covered)
    per_obj["(link-time partition)"]["ram"] = ram
    return per_obj


def by_source(footprint: dict[str, dict[str, int]]) -> dict[str, dict[str, int]]:
    """Objects keyed by source stem: CMake names them x.c.obj on bare metal and x.c.o on Linux."""
    return {re.sub(r"\.c\.o(bj)?$", "", k): v for k, v in footprint.items()}


def bundle_images(build_dir: Path) -> dict:
    """Which of its bundle's optional images a cross build has: the model store's (`store`) and the CANopen node's
    (`canopen`), and `why` not, as the build recorded them at configure time (firmware_c/cmake/target.cmake). A folder
    may still hold another bundle's images from an earlier build: only what the record names is this bundle's."""
    rec = run_record(build_dir)
    if "store_image" not in rec:
        return {"store": False, "canopen": False, "why": f"{build_dir} does not record its images (configure it again)"}
    return {"store": bool(rec["store_image"]), "canopen": bool(rec["canopen_image"]), "why": rec.get("images_why", ""),
            "bundle": rec.get("bundle")}


def model_slots_footprint(build_dir: Path) -> dict[str, int]:
    """Flash of the model-store objects and RAM of the store state, from the store test image
    (firmware_c/target/store_target.c) of a cross build."""
    image = Path(build_dir) / "slipest_store_target.elf"
    objs = library_footprint(Path(f"{image}.map"), "libslipest_q.a")
    nm = run_record(build_dir)["nm"]
    out = subprocess.run([nm, "-S", str(image)], capture_output=True, text=True, check=True).stdout
    m = re.search(r"^[0-9a-f]+ ([0-9a-f]+) [bB] store$", out, flags=re.M)
    if m is None:
        raise InputError(f"{image}: no 'store' symbol (slipest_store_t) in the symbol table")
    return {"flash": sum(o["flash"] for k, o in objs.items() if k in STORE_OBJECTS), "ram": int(m.group(1), 16),
            "objects": {k: v["flash"] for k, v in objs.items() if k in STORE_OBJECTS}}


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


def c_bench_inferences(bundle: Path) -> int:
    """Inferences per round of the host C bench: 100,000 for an SN-S (543 parameters), proportionally fewer for a
    larger model (about the same work: 4 x 256 units would take minutes per round), never fewer than the vectors."""
    from fleetlab.models import n_params

    arch = json.loads((Path(bundle) / "manifest.json").read_text()).get("arch", "sn-s")
    return max(1000, round(100_000 * n_params("sn-s") / n_params(arch)))


def host_timings(host_build: Path, bundle: Path, n: int, rounds: int = 3) -> dict[str, float]:
    """Best-of-rounds ns per inference; C, onnxruntime and torch interleaved so that load
    from other processes hits all of them alike."""
    calls = python_baselines(bundle, n)
    c_calls = str(c_bench_inferences(bundle))
    best = {"q": float("inf"), "f32": float("inf"), "onnxruntime": float("inf"), "torch": float("inf")}
    for _ in range(rounds):
        c = json.loads(run([str(host_build / "slipest_bench"), str(Path(bundle) / "vectors.bin"), c_calls]))
        best["q"] = min(best["q"], c["host_ns_per_inference_q"])
        best["f32"] = min(best["f32"], c["host_ns_per_inference_f32"])
        for key, fn in calls.items():
            best[key] = min(best[key], _time_per_call(fn, n))
    return best
