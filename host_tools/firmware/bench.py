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

The reference target's figures are keyed `<key>_*` (`m4_*` on the M4, `Target.key`); every target's
figures are under `cpu_targets`.
Where the guest has no counter QEMU drives (user-mode PowerPC, bare-metal SPARC), the cost image is run
under QEMU's one-instruction-per-block exec trace and the instructions between marks are counted; a
target with no counter at all (link-only) reports null with the reason, never an estimate.

This module runs the builds and formats the output; measure.py reads the images, maps and host timings;
figures.py assembles the figures from them; the options are `fleetlab.cli.bench_c`'s.
"""

from __future__ import annotations

import json
from pathlib import Path

from fleetlab.system_tools import need
from fleetlab.paths import build_root, default_bundle, repo_root

from . import targets as target_registry
from .build import cmake_build
from .figures import bench_figures, target_figures
from .measure import host_timings, target_costs
from fleetlab.errors import InputError


def list_targets() -> dict[str, dict]:
    """Every CPU target found (`targets.discover()`), as `--list-targets --json` prints them."""
    return {name: t.as_dict() for name, t in target_registry.discover().items()}


def targets_text() -> str:
    """Every CPU target found, one line each, as `--list-targets` prints them."""
    lines = []
    for name, t in target_registry.discover().items():
        flags = ", ".join([t.endian + "-endian", "FPU" if t.fpu else "no FPU"] + (["integer-only"] if t.integer_only else []))
        tree = repo_root()
        lines.append(f"{name:14s} {t.description} [{flags}] -- {t.emulator}  "
                     f"({t.file.relative_to(tree) if t.file.is_relative_to(tree) else t.file})")
    return "\n".join(lines)


def bench(bundle: Path | None = None, build_dir: Path | None = None, iterations: int = 2000, target: str | None = None,
          compare: Path | None = None, trap_unaligned: bool = False, progress: bool = True) -> dict:
    """Build `bundle` (default: the example bundle) for the host and for `target` (a name, 'all', or None: the
    reference target, always measured too) in `build_dir` (default: bench/ under the build root) and measure
    it; with `compare`, a second bundle's figures beside it (key "compare")."""
    from tqdm.auto import tqdm

    found = target_registry.discover()
    ref = target_registry.reference()
    names = [n for n, t in found.items() if t.runs] if target == "all" else [target_registry.get(target or ref.name).name]
    if not found[names[-1]].runs:
        raise InputError(f"target {names[-1]} is link-only (no emulator): nothing to measure")
    if ref.name not in names:
        names.insert(0, ref.name)  # the reference figures (and the figures) are always measured
    bundle = Path(bundle or default_bundle())
    if not (bundle / "vectors.bin").is_file():
        raise FileNotFoundError(f"{bundle}: no vectors.bin (not an export bundle?)")
    if trap_unaligned and (no_trap := [n for n in names if not found[n].unaligned_trap]):
        raise InputError(f"--trap-unaligned: {', '.join(no_trap)} cannot trap unaligned access "
                         f"(targets that can: {', '.join(n for n, t in found.items() if t.unaligned_trap)})")
    # always named, so a reused build folder never keeps the other choice from its cache
    options = {"SLIPEST_TRAP_UNALIGNED": "ON" if trap_unaligned else "OFF"}
    build_dir = Path(build_dir or build_root() / "bench")
    need("cmake", "fleetlab bench c")
    for name in names:
        found[name].need_tools(f"fleetlab bench c --target {name}")
    compare = Path(compare) if compare is not None else None
    if compare is not None and not (compare / "vectors.bin").is_file():
        raise FileNotFoundError(f"{compare}: no vectors.bin (not an export bundle?)")
    steps = tqdm(total=(2 + 2 * len(names)) * (2 if compare else 1), desc="bench c", leave=False,
                 disable=not progress)
    try:
        builds, t, ref_cost, rows = _measure(bundle, build_dir, names, found, ref, iterations, steps, options)
        result = bench_figures(ref, builds[ref.name], ref_cost, t, rows, bundle)
        result["arch"] = _arch_of(bundle)
        result["trap_unaligned"] = trap_unaligned
        if compare is not None:
            _, c_t, _, c_rows = _measure(compare, build_dir / "compare", names, found, None, iterations,
                                         steps, options)
            result["compare"] = {"bundle": str(compare), "arch": _arch_of(compare), "host_ns_per_inference_q": c_t["q"],
                                 "host_ns_per_inference_f32": c_t["f32"],
                                 "onnxruntime_ns_per_inference": c_t["onnxruntime"],
                                 "speedup_vs_onnxruntime": c_t["onnxruntime"] / c_t["q"], "cpu_targets": c_rows}
    finally:
        steps.close()  # cleared before anything else is printed: an error line is never written over by the bar
    return result


def _arch_of(bundle: Path) -> str:
    return json.loads((Path(bundle) / "manifest.json").read_text()).get("arch", "?")


def _measure(bundle: Path, build_dir: Path, names: list[str], found: dict, ref, iterations: int, steps, options: dict):
    """Build one bundle for the host and every target; host timings, the reference target's costs (measured
    once, shared by its row and the figures; None when no reference figures are wanted) and one row per target."""
    host = cmake_build(build_dir / "host", bundle)
    steps.update()
    builds = {}
    for name in names:
        builds[name] = cmake_build(build_dir / name, bundle, target=found[name], options=options)
        steps.update()
    t = host_timings(host, bundle, iterations)
    steps.update()
    ref_cost = target_costs(ref, builds[ref.name]) if ref is not None else None
    rows = {}
    for name in names:
        rows[name] = target_figures(found[name], builds[name], ref_cost if ref is not None and name == ref.name else None)
        steps.update()
    return builds, t, ref_cost, rows


def format_result(result: dict, key: str) -> str:
    """The plain-text output: one line per scalar figure, the CANopen node's parts and goals, the targets table,
    and a second bundle's figures beside the first when --compare gave one."""
    lines = [f"{k:42s} {v:.1f}" if isinstance(v, float) else f"{k:42s} {'n/a' if v is None else v}"
             for k, v in result.items() if not isinstance(v, dict)]
    co_node = result[f"{key}_canopen_node"]
    if "not_measured" not in co_node:
        parts = ", ".join(f"{k} {v}" for k, v in co_node["flash_bytes_by_part"].items())
        lines.append(f"{key + '_canopen_node_flash_by_part':42s} {parts}")
        lines.append(f"{key + '_canopen_node_ram_parts':42s} " +
                     ", ".join(f"{k} {v}" for k, v in co_node["ram_parts"].items()))
        lines.append(f"{key + '_canopen_node_goals':42s} {_goal_line(co_node)}")
    for what, why in result.get(f"{key}_not_measured", {}).items():
        lines.append(f"{key + '_' + what:42s} not measured for this bundle: {why}")
    lines.append("")
    lines.append(format_table(result["cpu_targets"]))
    cmp_result = result.get("compare")
    if cmp_result is not None:
        lines += ["", f"{'compare_bundle':42s} {cmp_result['bundle']} ({cmp_result['arch']})"]
        for k in ("host_ns_per_inference_q", "host_ns_per_inference_f32", "onnxruntime_ns_per_inference",
                  "speedup_vs_onnxruntime"):
            lines.append(f"{'compare_' + k:42s} {cmp_result[k]:.1f}")
        lines += ["", format_compare_table(result["arch"], result["cpu_targets"], cmp_result["arch"],
                                           cmp_result["cpu_targets"])]
    return "\n".join(lines)


def format_compare_table(arch_a: str, rows_a: dict[str, dict], arch_b: str, rows_b: dict[str, dict]) -> str:
    """Two architectures side by side per target (docs/integrating_slipest.md, "Choosing an architecture")."""
    head = (f"| target | instr./q inference {arch_a} | {arch_b} | instr./float inference {arch_a} | {arch_b} "
            f"| instr./sample (node) {arch_a} | {arch_b} "
            f"| flash kernel+model {arch_a} (B) | {arch_b} (B) | peak stack q {arch_a} (B) | {arch_b} (B) "
            f"| RAM {arch_a} (B) | {arch_b} (B) |")
    lines = [head, "|" + "---|" * 13]
    for name, a in rows_a.items():
        b = rows_b[name]
        cells = [(a[k], b[k]) for k in ("instructions_per_inference_q", "instructions_per_inference_f32",
                                          "instructions_per_sample_node_slcan", "flash_bytes_kernel_and_model",
                                          "stack_bytes_q", "ram_bytes")]
        lines.append(f"| {name} | " + " | ".join(f"{_cell(x)} | {_cell(y)}" for x, y in cells) + " |")
    return "\n".join(lines)


def _goal_line(co_node: dict) -> str:
    """The CANopen node's figures against their goals (issues 20 and 45), keyless and authenticating."""
    goals = co_node["goals"]

    def verdict(fig: dict, flash_goal: int) -> str:
        ok = fig["ram_bytes"] <= goals["ram_bytes"] and fig["flash_bytes"] <= flash_goal
        return f"RAM {fig['ram_bytes']}/{goals['ram_bytes']}, flash {fig['flash_bytes']}/{flash_goal} " \
               f"({'met' if ok else 'over'})"

    return (f"keyless {verdict(co_node, goals['flash_bytes'])}; "
            f"with HMAC {verdict(co_node['with_auth'], goals['auth_flash_bytes'])}")


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
