"""The figures `fleetlab bench c` reports, assembled from the measurements of measure.py.

* `target_figures`: one row per CPU target (instructions where counted, flash, peak stack);
* `canopen_node_figures`: RAM and flash of the CANopen node with two model slots, by part;
* `bench_figures`: the whole result (the store's and the CANopen node's figures measured on images of the given
  bundle's model.img, null with the reason under `<key>_not_measured` where the build has none). The reference
  target's figures (the target file marked
  SLIPEST_TARGET_REFERENCE) are keyed `<key>_*`, `<key>` being that target's `Target.key` (`m4` for the
  M4), so that docs and scripts can quote them by name; every target's row is under `cpu_targets`.

Flash is counted the same way everywhere: the library code and constants kept in a linked image (from its
linker map; startup, libc and the test harness excluded): by archive member, or, in the CANopen node images whose
library is optimised at link time, by source through the debug line table (measure.lto_footprint).
"""

from __future__ import annotations

import os
from pathlib import Path

from .build import run_image, run_record
from .measure import (STORE_OBJECTS, bundle_images, by_source, library_footprint, lto_footprint, model_slots_footprint,
                      parse_kv, target_costs)
from .targets import Target

SERIAL_LINK_OBJECTS = ("slipest_slcan", "slipest_cobs", "slipest_crc")
# the fixed-point kernels (the SN-S one and, in a layer-table build, the table one) plus the model as data: the
# bundle's const structs and its hash
KERNEL_AND_MODEL_OBJECTS = ("slipest_infer_q", "slipest_infer_table_q", "slipest_bundle_q", "slipest_model_hash")
# the CANopen node with two model slots (firmware_c/target/co_node_target.c), by part
CANOPEN_PARTS = {
    "canopen": ("slipest_co", "slipest_co_sdo", "slipest_co_od_access", "slipest_co_model", "slipest_co_od"),
    "store": ("slipest_store", "slipest_sha256", "slipest_image_stream", "slipest_image_v1", "slipest_image_buffer",
              "slipest_model"),
}
# issue 20: the whole CANopen node on the reference CPU; issue 45: the node that authenticates images
CANOPEN_GOALS = {"ram_bytes": 4096, "flash_bytes": 12288, "auth_flash_bytes": 13312}
# the reference CPU's goals (issue figures), by the suffix of their key
REFERENCE_GOALS = {"instructions_q": 3000, "flash_bytes": 6144, "ram_bytes": 1024}
SPEEDUP_GOAL = 20  # host: slipest q against onnxruntime on one window
COUNTED_BY = {"systick": "SysTick under qemu -icount shift=0",
              "instret": "minstret under qemu -icount shift=0",
              "trace": "qemu exec trace, one instruction per block"}
_ROW_COUNTS = ("instructions_per_inference_q", "instructions_per_inference_f32", "instructions_per_sample_node_slcan",
               "stack_bytes_q", "stack_bytes_f32", "stack_bytes_node_window", "ram_bytes")


def target_figures(t: Target, build_dir: Path, cost: dict | None = None) -> dict:
    """One row of the targets table: instruction counts (where counted), flash, peak stack and RAM.

    Flash: kernel + model in the fixed-point cost image; the CAN node (node, generated CAN codec,
    extractor, kernel + model, status) in the node-frames image, without the serial-link codecs
    (SLCAN, COBS, CRC) that image also links. `cost` is `target_costs(t, build_dir)` when the caller
    has measured it already (the images are run once)."""
    bench_map = build_dir / "slipest_bench_target_q.elf.map"
    kernel_map = bench_map if bench_map.is_file() else build_dir / "slipest_test_q.elf.map"
    lib = by_source(library_footprint(kernel_map, "libslipest_q.a"))
    node = by_source(library_footprint(build_dir / "slipest_node_frames.elf.map", "libslipest_q.a"))
    row: dict = {
        "description": t.description, "emulator": t.emulator, "endian": t.endian, "fpu": t.fpu,
        "integer_only": t.integer_only,
        "flash_bytes_kernel_and_model": sum(lib.get(k, {"flash": 0})["flash"] for k in KERNEL_AND_MODEL_OBJECTS),
        "flash_bytes_can_node": sum(o["flash"] for k, o in node.items() if k not in SERIAL_LINK_OBJECTS),
        "flash_bytes_by_object_can_node": {k: o["flash"] for k, o in sorted(node.items())},
    }
    if t.counter == "none":
        row.update(dict.fromkeys(_ROW_COUNTS))
        row["counted_by"] = (f"not counted: {t.emulator} has no instruction counter this bench reads "
                             "(-icount is system-mode only; Debian's QEMU ships no TCG plugins)")
        return row
    cost = cost or target_costs(t, build_dir)
    row.update({
        "instructions_per_inference_q": round(cost["q"], 1),
        "instructions_per_inference_f32": None if cost["f32"] is None else round(cost["f32"], 1),
        "instructions_per_sample_node_slcan": round(cost["node_instructions_per_sample"], 1),
        "stack_bytes_q": cost["stack_q"], "stack_bytes_f32": cost["stack_f32"],
        "stack_bytes_node_window": cost["stack_node_window"],
        # as the reference target's <key>_ram_bytes: the library's static data + node context + the peak
        # stack of the frame that closes a window (the layer-table kernel's scratch is on that stack)
        "ram_bytes": sum(o["ram"] for o in lib.values()) + cost["node_bytes"]
        + max(cost["stack_q"], cost["stack_node_window"]),
        "counted_by": COUNTED_BY[t.counter],
    })
    return row


def _canopen_image_figures(build_dir: Path, image: str) -> dict:
    out = run_image(build_dir, image)
    if "PASS" not in out:
        raise OSError(f"{build_dir}/{image} did not pass:\n{out[-1000:]}")
    kv = parse_kv(out)
    # the node's library is optimised at link time (target.cmake): its partitions, split by source
    lib = by_source(lto_footprint(build_dir / f"{image}.map", build_dir / image, build_dir / "libslipest_q.a",
                                  run_record(build_dir)))
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
    the library's code and constants in the image, optimised at link time as flight firmware is built, by source
    (node, CANopen, store, kernel; the flight image links no built-in model, its models are data in the slots);
    RAM = their static data + the node context + the store (one model in RAM, one sector buffer) + the peak stack
    of the heaviest call. The NVM area is
    the integrator's flash and is not counted. The main figures are the keyless node's; "with_auth" is
    the same node built to authenticate images (HMAC-SHA256 linked, signed images only)."""
    fig = _canopen_image_figures(build_dir, "slipest_co_node.elf")
    fig["with_auth"] = _canopen_image_figures(build_dir, "slipest_co_node_auth.elf")
    fig["goals"] = CANOPEN_GOALS
    return fig


def bench_figures(ref: Target, ref_build: Path, ref_cost: dict, host: dict[str, float], rows: dict[str, dict],
                  bundle: Path) -> dict:
    """The result of `fleetlab bench c`: host timings against the Python runtimes, the reference target's
    figures (`<ref.key>_*`, measured in `ref_build`, `ref_cost` its target_costs) and every target's row."""
    p = ref.key
    lib = library_footprint(ref_build / "slipest_bench_target_q.elf.map", "libslipest_q.a")
    # a CAN-attached flight firmware: the integration guide's main loop, no serial codec linked
    can_fw = library_footprint(ref_build / "example_minimal_can_loop.elf.map", "libslipest_q.a")
    # the store's and the CANopen node's figures come from images of this bundle's model.img; where the build has
    # none (a model beyond its image caps), the figures are null and `<key>_not_measured` says why
    images = bundle_images(ref_build)
    slots = model_slots_footprint(ref_build) if images["store"] else None
    co_node = canopen_node_figures(ref_build) if images["canopen"] else None
    not_measured = {name: images["why"] for name, fig in (("model_slots", slots), ("canopen_node", co_node))
                    if fig is None}
    flash = sum(o["flash"] for o in lib.values())
    static_ram = sum(o["ram"] for o in lib.values())
    kernel = sum(o["flash"] for k, o in by_source(lib).items() if k in KERNEL_AND_MODEL_OBJECTS)
    return {
        "host_ns_per_inference_q": host["q"],
        "host_ns_per_inference_f32": host["f32"],
        "onnxruntime_ns_per_inference": host["onnxruntime"],
        "torch_ns_per_inference": host["torch"],
        "speedup_vs_onnxruntime": host["onnxruntime"] / host["q"],
        "speedup_vs_torch": host["torch"] / host["q"],
        f"{p}_instructions_per_inference_q": round(ref_cost["q"], 1),
        f"{p}_instructions_per_inference_f32": round(ref_cost["f32"], 1),
        f"{p}_flash_bytes": flash,
        # static data + node context + peak stack of the frame that closes a window
        # (feature extraction, fixed-point inference, output frames)
        f"{p}_ram_bytes": static_ram + ref_cost["node_bytes"] + max(ref_cost["stack_q"], ref_cost["stack_node_window"]),
        f"{p}_flash_bytes_kernel_and_model": kernel,
        # a firmware uses one link: library + model without the SLCAN codec (COBS link only)
        f"{p}_flash_bytes_cobs_link_only": flash - lib.get("slipest_slcan.c.obj", {"flash": 0})["flash"],
        # library + model as linked into docs/integrating_slipest.md's CAN main loop (CAN peripheral, no serial link)
        f"{p}_flash_bytes_can_firmware": sum(o["flash"] for o in can_fw.values()),
        f"{p}_flash_bytes_by_object": {k: v["flash"] for k, v in sorted(lib.items())},
        # A/B model slots on NVM (docs/model_slots.md): store + SHA-256 + image reader, and slipest_store_t
        f"{p}_flash_bytes_model_slots": slots["flash"] if slots else None,
        f"{p}_ram_bytes_model_slots": slots["ram"] if slots else None,
        f"{p}_flash_bytes_can_node_with_slots": sum(o["flash"] for k, o in can_fw.items() if k not in STORE_OBJECTS)
        + slots["flash"] if slots else None,
        f"{p}_static_ram_bytes": static_ram,
        f"{p}_node_context_bytes": ref_cost["node_bytes"],
        f"{p}_stack_bytes_q": ref_cost["stack_q"],
        f"{p}_stack_bytes_f32": ref_cost["stack_f32"],
        f"{p}_stack_bytes_node_window": ref_cost["stack_node_window"],
        f"{p}_instructions_per_sample_node_slcan": round(ref_cost["node_instructions_per_sample"], 1),
        f"{p}_instructions_per_systick": ref_cost["instructions_per_tick"],
        f"{p}_label": ref.label,
        # the CANopen node with two model slots (issue 20 goal: <= 4 KB RAM, <= 12 KB flash)
        f"{p}_canopen_node_ram_bytes": co_node["ram_bytes"] if co_node else None,
        f"{p}_canopen_node_flash_bytes": co_node["flash_bytes"] if co_node else None,
        f"{p}_canopen_node_auth_ram_bytes": co_node["with_auth"]["ram_bytes"] if co_node else None,
        f"{p}_canopen_node_auth_flash_bytes": co_node["with_auth"]["flash_bytes"] if co_node else None,
        f"{p}_canopen_node": co_node if co_node else {"not_measured": images["why"]},
        f"{p}_not_measured": not_measured,
        "cpu_targets": rows,
        "targets": {**{f"{p}_{k}": v for k, v in REFERENCE_GOALS.items()}, "speedup_vs_onnxruntime": SPEEDUP_GOAL},
        "bundle": str(bundle),
        "host_cpu_count": os.cpu_count(),
    }
