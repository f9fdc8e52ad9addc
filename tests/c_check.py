"""The C kernels built straight with a compiler (no CMake) into the bundle-vector checker
(export/c/check_vectors.c): the paths and the strict flag set the kernel tests share."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
INCLUDE = REPO / "firmware_c" / "include"
# the fixed-point entry point with the SN-S kernel, the layer-table kernel, the float kernel
KERNELS = [REPO / "firmware_c" / "src" / "slipest_infer_q.c", REPO / "firmware_c" / "src" / "slipest_infer_table_q.c",
           REPO / "firmware_c" / "src" / "slipest_infer_f32.c"]
# model validation and the one vectors.bin reader, linked beside the kernels
SUPPORT = [REPO / "firmware_c" / "src" / "slipest_model.c", REPO / "firmware_c" / "common" / "slipest_vectors.c",
           REPO / "firmware_c" / "src" / "slipest_model_hash.c"]
COMMON = REPO / "firmware_c" / "common"
CHECK_SRC = REPO / "export" / "c" / "check_vectors.c"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]


def build_check(bundle: Path, out: Path, cc: str, flags: list[str]) -> Path:
    """The vector checker for `bundle`, compiled by `cc` with `flags` into `out`; fails the test on a warning."""
    exe = out / f"check_{Path(cc).name}"
    cmd = [cc, *STRICT, "-O2", *flags, f"-I{INCLUDE}", f"-I{COMMON}", f"-I{bundle}", str(CHECK_SRC),
           *map(str, KERNELS), *map(str, SUPPORT), "-lm", "-o", str(exe)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return exe


def check_argv(exe: Path, bundle: Path, tol: float | None = None) -> list[str]:
    """argv of the checker on `bundle`'s vectors.bin with the bundle's float tolerance (manifest.json
    float_tolerance, export/f32_bound.py), or `tol` for a folder without a manifest."""
    from fleetlab.export.f32_bound import recorded_tolerance

    if tol is None:
        tol = recorded_tolerance(json.loads((Path(bundle) / "manifest.json").read_text()))
    return [str(exe), str(Path(bundle) / "vectors.bin"), repr(float(tol))]
