"""The C inference kernels against the bundle vectors (host, UBSan/ASan), and their Cortex-M footprint."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from fleetlab.export.bundle import export_bundle
from fleetlab.export.vectors import draw_inputs

from c_check import INCLUDE, KERNELS, STRICT, SUPPORT, build_check, check_argv
from required import need_tool as need
from small_models import small_model

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"
ARM_GCC = "arm-none-eabi-gcc"


@pytest.fixture(scope="module")
def fresh_bundle(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cb") / "bundle"
    export_bundle(small_model(seed=9), out, inputs=draw_inputs(1000, None, seed=3))
    return out


@pytest.mark.parametrize("which", ["fresh", "example"])
def test_kernels_match_vectors_gcc_sanitized(which, fresh_bundle, tmp_path) -> None:
    bundle = fresh_bundle if which == "fresh" else EXAMPLE
    exe = build_check(bundle, tmp_path, need("gcc"), ["-fsanitize=undefined,address", "-fno-sanitize-recover=all"])
    res = subprocess.run(check_argv(exe, bundle), capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert re.search(r"q mismatches 0 .*f32 > tol 0", res.stdout)
    man = (bundle / "manifest.json").read_text()
    assert f'"content_hash32": "0x{re.search(r"hash32 0x([0-9a-f]{8})", res.stdout)[1]}"' in man


def test_kernels_match_vectors_clang(fresh_bundle, tmp_path) -> None:
    exe = build_check(fresh_bundle, tmp_path, need("clang"), ["-fsanitize=undefined", "-fsanitize-trap=undefined"])
    res = subprocess.run(check_argv(exe, fresh_bundle), capture_output=True, text=True, timeout=120)
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
    argv = check_argv(exe, fresh_bundle)
    argv[1] = str(bad)
    res = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert res.returncode == 1 and "q mismatches 1" in res.stdout


@pytest.mark.parametrize("cpu", ["cortex-m0", "cortex-m3", "cortex-m4"])
def test_fixed_point_kernel_has_no_float_and_fits(cpu, tmp_path) -> None:
    """No soft-float helper on a core without FPU; flash (code + model) <= 6 KB; no RAM but the stack."""
    cc = need(ARM_GCC)
    obj = tmp_path / "q.o"
    # the kernel and the example model (the const struct the bundle's header defines), as one object; an
    # SN-S bundle builds without the layer-table kernel (CMake's SLIPEST_LAYER_TABLE follows the bundle),
    # whose stack scratch is sized by the caps instead (test_layer_table_kernel_stack_follows_the_caps)
    base = [cc, *STRICT, "-Os", f"-mcpu={cpu}", "-mthumb", "-mfloat-abi=soft", "-fstack-usage", f"-I{INCLUDE}", f"-I{EXAMPLE}",
            "-DSLIPEST_LAYER_TABLE=0"]
    parts = []
    for src in (KERNELS[0], REPO / "firmware_c" / "src" / "slipest_bundle_q.c"):
        parts.append(tmp_path / (src.stem + ".o"))
        res = subprocess.run([*base, "-c", str(src), "-o", str(parts[-1])], capture_output=True, text=True, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    res = subprocess.run([need("arm-none-eabi-ld"), "-r", *map(str, parts), "-o", str(obj)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    (tmp_path / "q.su").write_text((tmp_path / "slipest_infer_q.su").read_text())
    nm = subprocess.run([need("arm-none-eabi-nm"), "-u", str(obj)], capture_output=True, text=True).stdout
    assert not re.search(r"__aeabi_[fd]|__(add|sub|mul|div)[sd]f3|__float|__fix", nm), nm
    sizes = subprocess.run([need("arm-none-eabi-size"), "-A", str(obj)], capture_output=True, text=True).stdout
    sec = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\S+)\s+(\d+)", sizes, re.M)}
    flash = sum(v for k, v in sec.items() if k.startswith((".text", ".rodata")))
    assert flash <= 6 * 1024, sizes
    assert sec.get(".data", 0) == 0 and sec.get(".bss", 0) == 0, sizes
    stack = max(int(m[1]) for m in re.finditer(r"\t(\d+)\t", (tmp_path / "q.su").read_text()))
    assert stack <= 512, (tmp_path / "q.su").read_text()


@pytest.mark.parametrize("width", [256, 128, 32])
def test_layer_table_kernel_stack_follows_the_caps(width, tmp_path) -> None:
    """The layer-table kernel's frame is its scratch, 6 bytes per unit of SLIPEST_MAX_WIDTH, plus a bounded
    rest; it has no .data/.bss and no soft-float helper on the M0."""
    cc = need(ARM_GCC)
    obj = tmp_path / "k.o"
    res = subprocess.run([cc, *STRICT, "-Os", "-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft", "-fstack-usage",
                          f"-I{INCLUDE}", f"-DSLIPEST_MAX_WIDTH={width}", "-c", str(KERNELS[1]), "-o", str(obj)],
                         capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    su = (tmp_path / "k.su").read_text()
    frames = {m[1]: int(m[2]) for m in re.finditer(r":(\w+)(?:\.\w+)*\t(\d+)\t", su)}
    assert 6 * width <= frames["slipest_infer_table_q"] <= 6 * width + 128, su
    nm = subprocess.run([need("arm-none-eabi-nm"), "-u", str(obj)], capture_output=True, text=True).stdout
    assert not re.search(r"__aeabi_[fd]|__(add|sub|mul|div)[sd]f3|__float|__fix", nm), nm


def test_c_counts_saturations_and_breaks_ties_like_the_reference(tmp_path) -> None:
    """Hand-made parameters whose LayerNorm output leaves int16 (C clips and counts like the reference)
    and whose classes 1 and 2 always tie (both pick the lower class)."""
    import numpy as np

    from fleetlab.export import headers, manifest, vectors
    from fleetlab.export.quant import FloatNet, gelu_table, quantize
    from fleetlab.models import build

    fp = FloatNet.from_model(build("sn-s", seed=4))
    qp = quantize(fp)
    blk = qp.blocks[0]
    blk.fy, blk.fg, blk.gelu = 12, 14, gelu_table(12)
    blk.g = np.full(30, 32767, np.int16)  # gamma ~ 2 ...
    blk.bb = np.full(30, 30000, np.int32)  # ... + beta ~ 7.3 in Q12: any z > 0.34 saturates u
    qp.w_out[2], qp.b_out[2] = qp.w_out[1], qp.b_out[1]  # logit 2 == logit 1 on every input
    headers.write_headers(tmp_path, qp, fp, manifest.content_hash(qp, fp))
    v = vectors.make_vectors(fp.to_model(), qp, draw_inputs(1000, None, seed=5))
    assert v.q_saturations.sum() > 1000
    assert (v.q_logits[:, 1] == v.q_logits[:, 2]).all() and not (v.q_class == 2).any()
    vectors.write_vectors(tmp_path, v)
    exe = build_check(tmp_path, tmp_path, need("gcc"), ["-fsanitize=undefined", "-fno-sanitize-recover=all"])
    from fleetlab.export.f32_bound import float_tolerance

    tol = float_tolerance(fp.to_model(), v.inputs)["tolerance"]
    res = subprocess.run(check_argv(exe, tmp_path, tol), capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr


TWO_MODELS_C = r"""
#include <stdio.h>
#include "slipest_infer.h"
#include "earth_q.h"
#include "fused_q.h"
int main(void)
{
    int16_t x[SLIPEST_N_FEATURES];
    int32_t a[SLIPEST_N_CLASSES], b[SLIPEST_N_CLASSES];
    long t;
    int j, differ = 0;
    if (slipest_model_q_check(&slipest_earth_q) != SLIPEST_OK || slipest_model_q_check(&slipest_fused_q) != SLIPEST_OK)
        return 3;
    for (t = 0; t < 2000; t++) {
        for (j = 0; j < SLIPEST_N_FEATURES; j++) x[j] = (int16_t)((t * 7919 + j * 104729) % 20001 - 10000);
        if (slipest_infer_q(&slipest_earth_q, x, a, 0) < 0 || slipest_infer_q(&slipest_fused_q, x, b, 0) < 0) return 4;
        if (b[0] - a[0] != DELTA || b[1] != a[1] || b[2] != a[2]) return 1;
        differ += slipest_infer_q(&slipest_earth_q, x, a, 0) != slipest_infer_q(&slipest_fused_q, x, b, 0);
    }
    printf("%08lx %08lx %d\n", (unsigned long)slipest_model_hash32(&slipest_earth_q),
           (unsigned long)slipest_model_hash32(&slipest_fused_q), differ);
    return 0;
}
"""


def test_two_bundles_in_one_image(tmp_path) -> None:
    """Two bundles' headers (an Earth and a 'fused' model) compile into one program and the kernel
    runs either through its const struct: the second differs by a head bias only, so its class-0
    logit is the first's + that bias on every input, and the two hashes differ."""
    from fleetlab.export import headers, manifest
    from fleetlab.export.bundle import load_bundle

    b = load_bundle(EXAMPLE)
    qp, fp = b.qparams, b.fparams
    (tmp_path / "earth_q.h").write_text(headers.q_header_text(qp, b.content_hash, "earth"))
    delta = 1 << 20
    qp.b_out = qp.b_out.copy()
    qp.b_out[0] += delta
    (tmp_path / "fused_q.h").write_text(headers.q_header_text(qp, manifest.content_hash(qp, fp), "fused", version=2))
    src = tmp_path / "two.c"
    src.write_text(TWO_MODELS_C)
    exe = tmp_path / "two"
    cmd = [need("gcc"), *STRICT, "-O2", "-fsanitize=undefined", "-fno-sanitize-recover=all", f"-DDELTA={delta}",
           f"-I{INCLUDE}", f"-I{tmp_path}", str(src), str(KERNELS[0]), str(KERNELS[1]), str(SUPPORT[0]), str(SUPPORT[2]),
           "-o", str(exe)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    res = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr
    h_earth, h_fused, differ = res.stdout.split()
    assert h_earth == b.content_hash[:8] and h_fused != h_earth
    assert int(differ) > 0  # the bias moves some argmax: the two models really are different data
