"""The references an estimator is checked against, from one export bundle.

- fixed-point: the torch integer reference `fleetlab.export.intref` (logits and saturations),
- float: the bundle's ONNX model under onnxruntime (the float C path's class).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Reference:
    bundle_dir: Path
    qparams: object
    model_hash32: int | None
    _onnx: object | None = None

    @classmethod
    def load(cls, bundle_dir: Path | str) -> "Reference":
        from fleetlab.export.bundle import load_bundle

        bundle_dir = Path(bundle_dir)
        b = load_bundle(bundle_dir)  # verifies hashes; refuses truncated/edited bundles
        return cls(bundle_dir, b.qparams, _hash32_of(b, bundle_dir))

    def q_logits(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """int16 features (N,12) -> (int logits (N,3), saturations (N,))."""
        from fleetlab.export.intref import q_logits_of

        logits, sat = q_logits_of(self.qparams, np.asarray(q, dtype=np.int16), return_saturations=True)
        return np.asarray(logits, dtype=np.int64), np.asarray(sat, dtype=np.int64)

    def f32_logits(self, x: np.ndarray) -> np.ndarray:
        """float features (N,12) in physical units -> float logits (N,3) from model.onnx."""
        if self._onnx is None:
            import onnxruntime as ort

            opts = ort.SessionOptions()
            opts.intra_op_num_threads = 1
            self._onnx = ort.InferenceSession(str(self.bundle_dir / "model.onnx"), opts,
                                              providers=["CPUExecutionProvider"])
        sess = self._onnx
        name = sess.get_inputs()[0].name  # type: ignore[attr-defined]
        return np.asarray(sess.run(None, {name: np.asarray(x, dtype=np.float32)})[0])  # type: ignore[attr-defined]


def _hash32_of(bundle, bundle_dir: Path) -> int | None:
    """First 4 bytes (big-endian) of the bundle content hash, as STATUS_MODEL reports it."""
    from fleetlab.export.manifest import hash32

    h = bundle.manifest.get("content_hash") if isinstance(bundle.manifest, dict) else None
    return hash32(h) if isinstance(h, str) else None
