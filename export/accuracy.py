"""How closely the fixed-point path follows the float model on real windows.

For every dataset folder and role: class agreement (fixed point vs float), logit error (fixed-point
logits divided by their scale, minus the float logits), balanced accuracy of both paths against the
labels. Targets (brief): agreement >= 99.5 %, balanced-accuracy loss <= 0.005.
The disagreement is split into its two causes: the int16 feature interface (the float model on
quantised features vs on float features) and the fixed-point arithmetic (fixed point vs the float
model on the same quantised features).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from sklearn.metrics import balanced_accuracy_score

from fleetlab.data.features_int import FEATURE_LSB, quantize_features

from .intref import argmax_lowest, run
from .quant import QNet

TARGET_AGREEMENT = 0.995
TARGET_BACC_LOSS = 0.005


def _bacc(y: np.ndarray, pred: np.ndarray) -> float:
    return float(balanced_accuracy_score(y, pred)) if len(np.unique(y)) > 1 else float(np.mean(y == pred))


def compare(model: torch.nn.Module, qp: QNet, x: np.ndarray, y: np.ndarray) -> dict:
    """Statistics of one set of windows (x float physical units, y labels)."""
    x = np.asarray(x, dtype=np.float32)
    with torch.no_grad():
        fl = model.eval()(torch.from_numpy(x)).numpy()
    xq, in_sat = quantize_features(x, return_saturations=True)
    with torch.no_grad():  # the float model on the int16 features it would get on the rover
        flq = model(torch.from_numpy((xq * FEATURE_LSB).astype(np.float32))).numpy()
    ql, q_sat = run(qp, xq)
    fc, qc, fqc = argmax_lowest(fl), argmax_lowest(ql), argmax_lowest(flq)
    err = np.abs(ql / qp.logit_scale - fl)
    bf, bq = _bacc(y, fc), _bacc(y, qc)
    return {
        "n": int(len(x)),
        "agreement": float(np.mean(fc == qc)),
        "disagreements": int(np.sum(fc != qc)),
        # split of the disagreement: int16 feature interface alone / fixed-point arithmetic alone
        "agreement_input_quantization": float(np.mean(fc == fqc)),
        "agreement_arithmetic": float(np.mean(fqc == qc)),
        "arith_logit_err_max": float(np.abs(ql / qp.logit_scale - flq).max()),
        "bacc_float": bf,
        "bacc_fixed": bq,
        "bacc_loss": bf - bq,
        "logit_err_mean": float(err.mean()),
        "logit_err_p99": float(np.quantile(err, 0.99)),
        "logit_err_max": float(err.max()),
        "input_saturations": int(in_sat),
        "q_saturations": int(q_sat.sum()),
    }


def report(model: torch.nn.Module, qp: QNet, data_dirs: list[Path]) -> dict:
    """Per dataset folder: every role, and all rows together."""
    from fleetlab.data.dataset import load_dataset

    out = {"targets": {"agreement": TARGET_AGREEMENT, "bacc_loss": TARGET_BACC_LOSS}, "datasets": []}
    for d in data_dirs:
        ds = load_dataset(d)
        entry = {"path": str(d), "roles": {}}
        xs, ys = [], []
        for role in ds.roles:
            x, y = ds.xy(role)
            entry["roles"][role] = compare(model, qp, x, y)
            xs.append(x)
            ys.append(y)
        entry["all"] = compare(model, qp, np.concatenate(xs), np.concatenate(ys))
        a = entry["all"]
        entry["meets_targets"] = bool(a["agreement"] >= TARGET_AGREEMENT and a["bacc_loss"] <= TARGET_BACC_LOSS)
        out["datasets"].append(entry)
    return out


def markdown(rep: dict) -> str:
    lines = [
        "# Fixed-point vs float accuracy",
        "",
        f"Targets: class agreement >= {rep['targets']['agreement']:.1%}, balanced-accuracy loss <= {rep['targets']['bacc_loss']}.",
        "Logit error: |fixed-point logits / logit scale - float logits|.",
        "",
        "Agreement split: *input* = float model on int16 features vs on float features (the feature",
        "interface alone); *arith* = fixed point vs float model on the same int16 features (the scheme alone).",
        "",
        "| data | role | windows | agreement | input / arith | bacc float | bacc fixed | loss | logit err mean / p99 / max | saturations in / q |",
        "|---|---|---:|---:|---|---:|---:|---:|---|---|",
    ]
    for d in rep["datasets"]:
        rows = list(d["roles"].items()) + [("all", d["all"])]
        for role, s in rows:
            lines.append(
                f"| {Path(d['path']).name} | {role} | {s['n']} | {s['agreement']:.4%} | "
                f"{s['agreement_input_quantization']:.4%} / {s['agreement_arithmetic']:.4%} | {s['bacc_float']:.4f} | "
                f"{s['bacc_fixed']:.4f} | {s['bacc_loss']:+.4f} | {s['logit_err_mean']:.2e} / {s['logit_err_p99']:.2e} / "
                f"{s['logit_err_max']:.2e} | {s['input_saturations']} / {s['q_saturations']} |"
            )
        lines.append("")
        lines.append(f"{Path(d['path']).name}: {'meets' if d['meets_targets'] else 'MISSES'} the targets.")
        lines.append("")
    return "\n".join(lines) + "\n"


def write_report(bundle: Path, rep: dict) -> list[Path]:
    bundle = Path(bundle)
    (bundle / "accuracy.json").write_text(json.dumps(rep, indent=2) + "\n")
    (bundle / "accuracy.md").write_text(markdown(rep))
    return [bundle / "accuracy.json", bundle / "accuracy.md"]
