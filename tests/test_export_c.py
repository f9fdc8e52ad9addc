"""The C inference kernels against the bundle vectors (host, UBSan/ASan), and their Cortex-M footprint."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from fleetlab.export.bundle import export_bundle
from fleetlab.export.vectors import draw_inputs

REPO = Path(__file__).resolve().parents[1]
INCLUDE = REPO / "firmware_c" / "include"
KERNELS = [REPO / "firmware_c" / "src" / "slipest_infer_q.c", REPO / "firmware_c" / "src" / "slipest_infer_f32.c"]
CHECK_SRC = REPO / "export" / "c" / "check_vectors.c"
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
ARM_GCC = "arm-none-eabi-gcc"


def need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pytest.skip(f"{tool} is not installed (scripts/setup.sh installs it)")
    return path


@pytest.fixture(scope="module")
def fresh_bundle(tmp_path_factory) -> Path:
    from test_export_bundle import small_model

    out = tmp_path_factory.mktemp("cb") / "bundle"
    export_bundle(small_model(seed=9), out, inputs=draw_inputs(1000, None, seed=3))
    return out


def build_check(bundle: Path, out: Path, cc: str, flags: list[str]) -> Path:
    exe = out / f"check_{Path(cc).name}"
    cmd = [cc, *STRICT, "-O2", *flags, f"-I{INCLUDE}", f"-I{bundle}", str(CHECK_SRC), *map(str, KERNELS), "-lm", "-o", str(exe)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return exe


@pytest.mark.parametrize("which", ["fresh", "example"])
def test_kernels_match_vectors_gcc_sanitized(which, fresh_bundle, tmp_path) -> None:
    bundle = fresh_bundle if which == "fresh" else EXAMPLE
    exe = build_check(bundle, tmp_path, need("gcc"), ["-fsanitize=undefined,address", "-fno-sanitize-recover=all"])
    res = subprocess.run([str(exe), str(bundle / "vectors.bin")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert re.search(r"q mismatches 0 .*f32 > tol 0", res.stdout)
    man = (bundle / "manifest.json").read_text()
    assert re.search(r"hash32 0x([0-9a-f]{8}) ([0-9a-f]{64})", res.stdout)[2] in man


def test_kernels_match_vectors_clang(fresh_bundle, tmp_path) -> None:
    exe = build_check(fresh_bundle, tmp_path, need("clang"), ["-fsanitize=undefined", "-fsanitize-trap=undefined"])
    res = subprocess.run([str(exe), str(fresh_bundle / "vectors.bin")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr


def test_check_program_detects_a_wrong_logit(fresh_bundle, tmp_path) -> None:
    """The checker is not vacuous: one flipped reference logit makes it fail."""
    exe = build_check(fresh_bundle, tmp_path, need("gcc"), [])
    data = bytearray((fresh_bundle / "vectors.bin").read_bytes())
    import json

    arrays = {a["name"]: a for a in json.loads((fresh_bundle / "manifest.json").read_text())["vectors"]["bin"]["arrays"]}
    data[arrays["q_logits"]["offset"] + 4 * 10] ^= 1
    bad = tmp_path / "bad.bin"
    bad.write_bytes(bytes(data))
    res = subprocess.run([str(exe), str(bad)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 1 and "q mismatches 1" in res.stdout


@pytest.mark.parametrize("cpu", ["cortex-m0", "cortex-m3", "cortex-m4"])
def test_fixed_point_kernel_has_no_float_and_fits(cpu, tmp_path) -> None:
    """No soft-float helper on a core without FPU; flash (code + model) <= 6 KB; no RAM but the stack."""
    cc = need(ARM_GCC)
    obj = tmp_path / "q.o"
    cmd = [cc, *STRICT, "-Os", f"-mcpu={cpu}", "-mthumb", "-mfloat-abi=soft", "-fstack-usage", f"-I{INCLUDE}", f"-I{EXAMPLE}",
           "-c", str(KERNELS[0]), "-o", str(obj)]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    nm = subprocess.run([need("arm-none-eabi-nm"), "-u", str(obj)], capture_output=True, text=True).stdout
    assert not re.search(r"__aeabi_[fd]|__(add|sub|mul|div)[sd]f3|__float|__fix", nm), nm
    sizes = subprocess.run([need("arm-none-eabi-size"), "-A", str(obj)], capture_output=True, text=True).stdout
    sec = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\S+)\s+(\d+)", sizes, re.M)}
    flash = sum(v for k, v in sec.items() if k.startswith((".text", ".rodata")))
    assert flash <= 6 * 1024, sizes
    assert sec.get(".data", 0) == 0 and sec.get(".bss", 0) == 0, sizes
    stack = max(int(m[1]) for m in re.finditer(r"\t(\d+)\t", (tmp_path / "q.su").read_text()))
    assert stack <= 512, (tmp_path / "q.su").read_text()


def test_c_counts_saturations_and_breaks_ties_like_the_reference(tmp_path) -> None:
    """Hand-made parameters whose LayerNorm output leaves int16 (C clips and counts like the reference)
    and whose classes 1 and 2 always tie (both pick the lower class)."""
    import numpy as np

    from fleetlab.export import headers, manifest, vectors
    from fleetlab.export.quant import FloatParams, gelu_table, quantize
    from fleetlab.models import build

    fp = FloatParams.from_model(build("sn-s", seed=4))
    qp = quantize(fp)
    qp.fy, qp.fg, qp.gelu = 12, 14, gelu_table(12)
    qp.g = np.full(30, 32767, np.int16)  # gamma ~ 2 ...
    qp.bb = np.full(30, 30000, np.int32)  # ... + beta ~ 7.3 in Q12: any z > 0.34 saturates u
    qp.w2[2], qp.b2[2] = qp.w2[1], qp.b2[1]  # logit 2 == logit 1 on every input
    headers.write_headers(tmp_path, qp, fp, manifest.content_hash(qp, fp))
    v = vectors.make_vectors(fp.to_model(), qp, draw_inputs(1000, None, seed=5))
    assert v.q_saturations.sum() > 1000
    assert (v.q_logits[:, 1] == v.q_logits[:, 2]).all() and not (v.q_class == 2).any()
    vectors.write_vectors(tmp_path, v)
    exe = build_check(tmp_path, tmp_path, need("gcc"), ["-fsanitize=undefined", "-fno-sanitize-recover=all"])
    res = subprocess.run([str(exe), str(tmp_path / "vectors.bin")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
