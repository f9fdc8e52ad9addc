"""The CPU-sensitive checks, run as other x86-64 CPUs and compared with this one (issue 42).

MKL, OpenBLAS and torch pick their kernels by CPU vendor and instruction set, so a float result can
change in its last bit from one CPU to another. docs/architecture.md ("Same bits where") says which
outputs must be the same bits on every machine and which only on one. This test starts
tests/cross_cpu_probe.py in processes that QEMU user mode runs as an Intel Haswell and an AMD EPYC-Rome
(both AVX2, no AVX-512; this machine may be anything), and demands:

- the every-machine outputs (erf table, the export of fixed weights: both headers, the model image, ONNX,
  every integer column of the test vectors) equal, byte for byte, what this machine writes; torch's float
  logits equal to rounding;
- the one-machine checks (fitness in pieces and kept buffers, sharing one call's rows, seeded search, lockstep
  runs alone and together) pass on each emulated CPU by itself.

On the fitness code before issue 42 the second part failed on both CPUs (and on a native AMD Zen 4): a lone
model's J differed in its last bit from its J inside a batch, which a test there demanded.
"""

from __future__ import annotations

import concurrent.futures
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from required import need_tool

HERE = Path(__file__).resolve().parent
PROBE = HERE / "cross_cpu_probe.py"
CPUS = ("Haswell-v4", "EPYC-Rome-v2")
EXACT_FILES = ("erf/slipest_erf_f32.h", "bundle/slipest_model_q.h", "bundle/slipest_model_f32.h",
               "bundle/model.img", "bundle/model.onnx")
FLOAT_COLUMNS = ("torch_logits",)  # torch's float forward: equal to rounding only


def _probe(cmd: list[str], out: Path) -> Path:
    # natively only the exports, to compare with: the suite itself runs the one-machine checks on this CPU
    extra = [] if cmd else ["--exports-only"]
    res = subprocess.run([*cmd, sys.executable, str(PROBE), str(out), *extra], capture_output=True, text=True,
                         timeout=900)
    assert res.returncode == 0, f"{cmd}: {res.stderr[-3000:]}"
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    qemu = need_tool("qemu-x86_64")
    tmp = tmp_path_factory.mktemp("cpus")
    jobs = {"native": []} | {cpu: [qemu, "-cpu", cpu] for cpu in CPUS}
    with concurrent.futures.ThreadPoolExecutor(len(jobs)) as pool:
        futures = {name: pool.submit(_probe, cmd, tmp / name) for name, cmd in jobs.items()}
        return {name: f.result() for name, f in futures.items()}


@pytest.mark.parametrize("cpu", CPUS)
def test_one_machine_checks_hold_on_each_cpu(runs, cpu):
    status, summary = (runs[cpu] / "checks.txt").read_text().split("\n", 1)
    assert status == "0", f"{cpu}:\n{summary}"
    assert " passed" in summary and "deselected" in summary, summary


@pytest.mark.parametrize("cpu", CPUS)
def test_every_machine_outputs_are_the_same_bytes(runs, cpu):
    native, other = runs["native"], runs[cpu]
    for name in EXACT_FILES:
        assert (native / name).read_bytes() == (other / name).read_bytes(), f"{cpu}: {name}"
    a, b = np.load(native / "bundle" / "vectors.npz"), np.load(other / "bundle" / "vectors.npz")
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        if key in FLOAT_COLUMNS:
            scale = np.maximum(1.0, np.abs(a[key]))
            assert np.all(np.abs(a[key] - b[key]) <= 1e-6 * scale), f"{cpu}: {key}"
        else:
            assert np.array_equal(a[key], b[key]), f"{cpu}: {key}"
