"""Every generator whose output is committed or compared byte for byte gives the same bytes on every CPU.

Issue 26: the erf table's least-squares fit went through OpenBLAS, whose kernel is picked by CPU, so the
committed header differed in its last bits on a machine without AVX-512. Here each generator
(tests/generate_artifacts.py: erf table, CANopen tables and EDS, DBC codec, seeded training, an export
bundle, the example bundle's generator) runs in subprocesses under different OpenBLAS kernels
(OPENBLAS_CORETYPE=Prescott and Haswell) and with numpy's CPU dispatch reduced to its baseline
(NPY_DISABLE_CPU_FEATURES naming every dispatched feature this CPU has), and every file must be equal.
torch does not use OpenBLAS: its own kernels are compared the same way (ATen's AVX2 against AVX-512), and
its portable scalar kernels, where seeded init differs (see test_torch_scalar_kernels_change_only_floats).

The negative control runs the old fit (numpy's Chebyshev.fit) under the two OpenBLAS kernels and sees a
difference: the comparison here is able to catch a BLAS-dependent generator.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

SCRIPT = Path(__file__).resolve().parent / "generate_artifacts.py"
BLAS_KERNELS = ("Prescott", "Haswell")


def _baseline_env() -> dict[str, str]:
    """numpy's dispatch reduced to the baseline: every dispatched feature this CPU has, disabled (naming a
    baseline feature there is an error; naming one the CPU lacks does nothing)."""
    on = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(on)} if on else {}


def _run(out: Path, env: dict[str, str], *args: str) -> Path:
    full = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES",
                                                           "ATEN_CPU_CAPABILITY")}
    res = subprocess.run([sys.executable, str(SCRIPT), str(out), *args], env={**full, **env},
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"{env}: {res.stderr[-2000:]}"
    return out


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _same(a: Path, b: Path, what: str) -> None:
    fa, fb = _files(a), _files(b)
    assert sorted(fa) == sorted(fb), what
    differ = [name for name in fa if fa[name] != fb[name]]
    assert not differ, f"{what}: different bytes in {differ}"


@pytest.fixture(scope="module")
def variants(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("determinism")
    runs = {k: _run(tmp / k, {"OPENBLAS_CORETYPE": k}) for k in BLAS_KERNELS}
    runs["numpy-baseline"] = _run(tmp / "numpy-baseline", _baseline_env())
    return runs


def test_the_variants_really_ran_on_different_kernels(variants):
    archs = []
    for kernel in BLAS_KERNELS:  # OpenBLAS names the kernel it loaded (Prescott reports itself as "Katmai")
        info = json.loads(variants[kernel].with_name(f"{kernel}.kernels.json").read_text())
        archs.append({lib["architecture"] for lib in info if lib.get("internal_api") == "openblas"})
    assert all(len(a) == 1 for a in archs) and archs[0] != archs[1], archs
    if _baseline_env():
        env = {**os.environ, **_baseline_env()}
        code = "from numpy._core._multiarray_umath import __cpu_features__ as f, __cpu_dispatch__ as d; " \
               "print(sum(bool(f[x]) for x in d))"
        res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        assert res.stdout.strip() == "0"


def test_every_generator_gives_the_same_bytes_on_every_kernel(variants):
    names = sorted(_files(variants["Prescott"]))
    for generator in ("erf", "canopen", "dbc", "training", "bundle", "example"):
        assert any(n.startswith(generator + "/") for n in names), generator
    for name, out in variants.items():
        if name != "Prescott":
            _same(variants["Prescott"], out, f"Prescott vs {name}")


def test_committed_erf_header_is_what_every_kernel_generates(variants):
    committed = Path(__file__).resolve().parents[1] / "firmware_c" / "src" / "slipest_erf_f32.h"
    assert committed.read_bytes() == (variants["Prescott"] / "erf" / "slipest_erf_f32.h").read_bytes()


def test_negative_control_the_old_least_squares_erf_fit_differs(tmp_path):
    """The pre-issue-26 generator, Chebyshev.fit, gives different float32 coefficients on the two kernels:
    the comparison above would have caught it."""
    a, b = (_run(tmp_path / k, {"OPENBLAS_CORETYPE": k}, "--old-erf") for k in BLAS_KERNELS)
    assert (a / "old_erf.txt").read_text() != (b / "old_erf.txt").read_text()


@pytest.mark.skipif(not __cpu_features__.get("AVX512F"), reason="ATen's AVX-512 kernels need a CPU with AVX-512F "
                    "(this one has none; the AVX2 kernels still run in the other tests)")
def test_torch_avx2_and_avx512_kernels_agree(tmp_path, variants):
    """Seeded init, training and export under ATen's AVX2 kernels equal the default AVX-512 run."""
    out = _run(tmp_path / "avx2", {"ATEN_CPU_CAPABILITY": "avx2"}, "--only", "training,bundle,example")
    for generator in ("training", "bundle", "example"):
        _same(variants["Prescott"] / generator, out / generator, f"ATen avx2 vs avx512: {generator}")


def test_torch_scalar_kernels_change_only_floats(tmp_path, variants):
    """ATen's portable kernels (a CPU without AVX2, or ATEN_CPU_CAPABILITY=default) round torch's float
    forward differently in the last bit. Exporting the same weights must still give the same integer model:
    both headers, the model image, ONNX, every vector column but torch's float logits, which differ by rounding
    only. (Seeded init and training there differ too: the example bundle is therefore committed data,
    checked on every machine by check_bundle, not regenerated.)"""
    out = _run(tmp_path / "scalar", {"ATEN_CPU_CAPABILITY": "default"}, "--only", "bundle")
    ref, got = variants["Prescott"] / "bundle", out / "bundle"
    for name in ("slipest_model_q.h", "slipest_model_f32.h", "model.img", "model.onnx"):
        assert (ref / name).read_bytes() == (got / name).read_bytes(), name
    a, b = np.load(ref / "vectors.npz"), np.load(got / "vectors.npz")
    for key in a.files:
        if key != "torch_logits":
            assert np.array_equal(a[key], b[key]), key
    scale = np.maximum(1.0, np.abs(a["torch_logits"]))  # rounding only: far inside the bundle's 1e-5 rule
    assert np.all(np.abs(a["torch_logits"] - b["torch_logits"]) <= 1e-6 * scale)
