"""ONNX export of a fleetlab model (eval mode: dropout gone) and its parity check with onnxruntime."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import torch
from fleetlab.errors import InputError

OPSET = 17  # first opset with a native LayerNormalization
INPUT_NAME, OUTPUT_NAME = "features", "logits"


def export_onnx(model: torch.nn.Module, path: Path, opset: int = OPSET) -> int:
    """Write `model` as ONNX with a dynamic batch dimension; return the opset used.

    The TorchScript-based exporter is used because it needs no extra package (the dynamo
    exporter needs onnxscript); it is deterministic for this plain MLP.
    """
    import onnx

    model = model.eval()
    example = torch.zeros(2, model.linears[0].in_features)
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            model, (example,), buf, input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
            dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}},
            opset_version=opset, dynamo=False, do_constant_folding=True,
        )
    proto = onnx.load_from_string(buf.getvalue())
    onnx.checker.check_model(proto, full_check=True)
    Path(path).write_bytes(buf.getvalue())
    return opset


def onnx_logits(path: Path, inputs: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    return sess.run([OUTPUT_NAME], {INPUT_NAME: np.asarray(inputs, dtype=np.float32)})[0]


def check_onnx(path: Path, inputs: np.ndarray, torch_logits: np.ndarray, tol: float) -> tuple[float, float]:
    """onnx.checker + onnxruntime outputs within tol * max(1, |torch logit|) of the torch logits, tol being the
    bundle's float tolerance (export/f32_bound.py: what float32 rounding allows for this network on these inputs);
    returns the max |diff| and the max |diff| / max(1, |torch logit|)."""
    import onnx

    from .f32_bound import excess

    path = Path(path)
    try:
        onnx.checker.check_model(onnx.load(str(path)), full_check=True)
    except Exception as e:  # onnx raises its own error types for a damaged file
        raise InputError(f"{path}: ONNX checker failed ({type(e).__name__}: {e})") from None
    out = onnx_logits(path, inputs)
    if out.shape != np.shape(torch_logits):
        raise InputError(f"{path}: onnxruntime output shape {out.shape}, expected {np.shape(torch_logits)}")
    diff = float(np.abs(out - torch_logits).max(initial=0.0))
    scaled = excess(out, torch_logits)
    if not scaled <= tol:
        raise InputError(f"{path}: onnxruntime logits differ from torch by {diff:.3g} "
                         f"({scaled:.3g} x max(1, |logit|) > the bundle's float tolerance {tol:.3g})")
    return diff, scaled
