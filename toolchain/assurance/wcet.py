"""Worst-case instruction counts of slipest_infer_q, slipest_extractor_push and slipest_node_handle on a
SysTick CPU target (default: the reference target, Cortex-M4), from the image firmware_c/target/wcet_target.c
run under qemu -icount shift=0.

Each case is timed over REPS identical calls (state restored from a snapshot, the restore timed alone and
subtracted), so a count is exact to 40/REPS instructions; the figures are the MAXIMUM MEASURED over the
bundle vectors and over inputs built to reach the long paths (the case list is in wcet_target.c). They are
not a static bound: a path no case takes is not counted. Counts include the few instructions of the
image's call wrapper (arguments, result), so they slightly over-count the function alone.

    fleetlab assure wcet [--bundle DIR] [--target NAME] [--build DIR]
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fleetlab.host_tools.firmware import targets as target_registry
from fleetlab.host_tools.firmware.measure import parse_kv
from fleetlab.host_tools.firmware.build import cmake_build, run_image
from ..errors import InputError

IMAGE = "slipest_wcet_target_q.elf"
# (function, key in the image's output, overhead key, what the cases are)
ROWS = [
    ("slipest_infer_q", "infer_vectors", "overhead_call_ticks", "bundle vectors"),
    ("slipest_infer_q", "infer_built", "overhead_call_ticks",
     "built inputs: extremes, per-unit full-scale patterns, single features, random magnitudes"),
    ("slipest_extractor_push", "push", "overhead_push_ticks",
     "stream: in order, window close, close after a gap, two windows in one call, late/duplicate, reset"),
    ("slipest_node_handle", "node", "overhead_node_ticks",
     "telemetry at full scale (saturated std), windows closed after a gap, status frames, FEATURES, control"),
]


@dataclass
class WorstCase:
    function: str
    cases: str
    n_cases: int
    instructions: float
    worst_case_index: int


def parse(text: str) -> list[WorstCase]:
    kv = parse_kv(text)
    missing = [k for k in ("calib_instructions", "calib_ticks", "reps") if k not in kv]
    if missing:
        raise InputError(f"{IMAGE}: output lacks {missing}:\n{text[-2000:]}")
    per_tick = kv["calib_instructions"] / kv["calib_ticks"]
    rows = []
    for fn, key, overhead, what in ROWS:
        ticks = kv[f"{key}_ticks"] - kv[overhead]
        rows.append(WorstCase(fn, what, kv[f"{key}_cases"], ticks * per_tick / kv["reps"], kv[f"{key}_case"]))
    return rows


def measure(build: Path, bundle: Path | None = None, target: str | None = None) -> tuple[str, list[WorstCase]]:
    """Build the worst-case image for `target` (a SysTick target) and run it; (target description, rows)."""
    t = target_registry.get(target) if target else target_registry.reference()
    if t.counter != "systick":
        raise InputError(f"{t.name}: the worst-case image needs a SysTick counter (counter is {t.counter!r})")
    cmake_build(build, bundle, target=t, targets=("slipest_wcet_target_q",))
    return t.description, parse(run_image(build, IMAGE, icount=True, timeout=900))


def per_function(rows: list[WorstCase]) -> dict[str, float]:
    """Maximum over all case groups, per function."""
    out: dict[str, float] = {}
    for r in rows:
        out[r.function] = max(out.get(r.function, 0.0), r.instructions)
    return out


def table(rows: list[WorstCase]) -> str:
    lines = ["| Function | Cases | Count | Max instructions (measured) |", "|---|---|---:|---:|"]
    lines += [f"| {r.function} | {r.cases} | {r.n_cases} | {r.instructions:.0f} |" for r in rows]
    return "\n".join(lines)
