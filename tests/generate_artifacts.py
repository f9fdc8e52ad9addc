"""Run every generator whose output is committed or compared byte for byte, into one folder.

    python tests/generate_artifacts.py OUTDIR [--only erf,canopen,dbc,bundle,example]

tests/test_determinism.py runs this in subprocesses under different OpenBLAS kernels and with numpy's CPU
dispatch reduced to its baseline, and demands the same bytes from every run. `--old-erf` runs the
least-squares erf fit this project used before issue 26 (numpy's Chebyshev.fit, an OpenBLAS solve): the
test's negative control, which must differ between kernels.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def erf(out: Path) -> None:
    from fleetlab.export import erf_table

    (out / "slipest_erf_f32.h").write_text(erf_table.header())


def old_erf(out: Path) -> None:
    """The pre-issue-26 fit: Chebyshev.fit (least squares through OpenBLAS), float32-rounded like the header."""
    from numpy.polynomial import Chebyshev, Polynomial
    from scipy.special import erf as sp_erf

    rows = []
    for k in range(8):
        lo, hi = k * 0.5, (k + 1) * 0.5
        c = 0.0 if k == 0 else (lo + hi) / 2
        t = (lo + hi) / 2 - c + (hi - lo) / 2 * np.cos(np.pi * (np.arange(256) + 0.5) / 256)
        f = (lambda x: sp_erf(x) / x) if k == 0 else (lambda u, c=c: sp_erf(c + u))
        fit = Chebyshev.fit(t, f(t), 6 if k == 0 else 7, domain=[lo - c, hi - c])
        rows.append(np.float32(fit.convert(kind=Polynomial, domain=[-1, 1], window=[-1, 1]).coef).tobytes().hex())
    (out / "old_erf.txt").write_text("\n".join(rows) + "\n")


def canopen(out: Path) -> None:
    gen = [sys.executable, str(REPO / "canopen_od" / "generate.py")]
    subprocess.run([*gen, "c", str(out)], check=True)
    subprocess.run([*gen, "eds", str(out / "slipest.eds")], check=True)
    (out / "od.md").write_text(subprocess.run([*gen, "md"], check=True, capture_output=True, text=True).stdout)


def dbc(out: Path) -> None:
    """The integer-only C codec of the DBC, by the CMake build's own generation script."""
    from fleetlab.dbc import DBC_PATH

    subprocess.run(["cmake", f"-DPYTHON={sys.executable}", f"-DDBC={DBC_PATH}", f"-DGEN={out}", "-P",
                    str(REPO / "firmware_c" / "cmake" / "generate_dbc.cmake")], check=True, capture_output=True)


def _small_model(steps: int):
    """A seeded SN-S trained `steps` Adam steps on built-in windows with a rule-based label (one thread)."""
    import torch

    from fleetlab.export.vectors import builtin_windows
    from fleetlab.models import build
    from fleetlab.models.train import train_classifier

    torch.set_num_threads(1)
    x = builtin_windows(400, np.random.default_rng(3)).astype(np.float32)
    y = np.digitize(x[:, 3] / np.maximum(x[:, 2], 1e-3), [0.08, 0.3]).astype(np.int64)
    return train_classifier(build("sn-s", seed=3), x, y, steps=steps, seed=3)


def training(out: Path) -> None:
    """Seeded training's weights, raw float32 bytes."""
    model = _small_model(60)
    (out / "weights.bin").write_bytes(b"".join(p.detach().numpy().tobytes() for p in model.state_dict().values()))


def _fixed_model():
    """An SN-S whose weights come from numpy's PCG64 alone (torch's own seeded init and training depend on
    torch's CPU kernels: see tests/test_determinism.py), scaled like a trained net's."""
    import torch

    from fleetlab.models import build

    model = build("sn-s", seed=0)
    rng = np.random.default_rng(7)
    with torch.no_grad():
        for p in model.parameters():
            fan_in = p.shape[1] if p.ndim == 2 else 4
            p.copy_(torch.from_numpy(rng.uniform(-1.5, 1.5, p.shape).astype(np.float32) / np.float32(fan_in) ** 0.5))
    return model.eval()


def bundle(out: Path) -> None:
    """`fleetlab export` of fixed weights: export scales, both headers, vectors, model image, ONNX, manifest."""
    from fleetlab.export.bundle import export_bundle
    from fleetlab.export.vectors import builtin_windows

    export_bundle(_fixed_model(), out, inputs=builtin_windows(200, np.random.default_rng(4)), meta={"seed": 7})


def example(out: Path) -> None:
    """The example bundle's generator (`python -m fleetlab.cli.example_bundle`) at a small scale."""
    from fleetlab.export.example import make_example

    make_example(out / "example", seed=1, scale=0.05, epochs=2)


GENERATORS = {"erf": erf, "canopen": canopen, "dbc": dbc, "training": training, "bundle": bundle, "example": example}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--only", default=",".join(GENERATORS), help="comma-separated generators")
    ap.add_argument("--old-erf", action="store_true", help="run only the old least-squares erf fit")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.old_erf:
        old_erf(args.out)
        return 0
    for name in args.only.split(","):
        d = args.out / name
        d.mkdir(exist_ok=True)
        GENERATORS[name](d)
    from threadpoolctl import threadpool_info

    (args.out.parent / f"{args.out.name}.kernels.json").write_text(json.dumps(threadpool_info(), default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
