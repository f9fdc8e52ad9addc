"""manifest.json of a bundle and the content hash that the C estimator reports at run time.

The content hash is sha256 over a canonical serialisation of the model content: the scheme
scalars (JSON, sorted keys), then every integer array of the fixed-point path and every float32
array of the float path, each preceded by its name, dtype and shape, little-endian bytes.
Both C headers name it, their model structs carry its first 4 bytes (big-endian) as hash32, and
model.img ends with it.
The manifest also lists the sha256 and size of every other bundle file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from .quant import FloatBlock, FloatNet, FloatParams, QBlock, QNet, QParams

MANIFEST = "manifest.json"
FORMAT = "fleetlab-bundle/1"
CONTENT_TAG = b"fleetlab-slipest-model/1\n"


def _feed(h, name: str, arr: np.ndarray, dtype: str) -> None:
    a = np.ascontiguousarray(np.asarray(arr).astype(dtype))
    h.update(f"{name}:{a.dtype.str}:{list(a.shape)}\n".encode())
    h.update(a.tobytes())


def content_hash(qp: QParams | None, fp: FloatParams) -> str:
    """sha256 hex of the canonical SN-S model content (fixed-point part absent for ONNX-only bundles)."""
    h = hashlib.sha256(CONTENT_TAG)
    if qp is not None:
        h.update(json.dumps(qp.scalars(), sort_keys=True, separators=(",", ":")).encode() + b"\n")
        for name in QParams.INT_ARRAYS:
            _feed(h, "q." + name, getattr(qp, name), "<i8")
    h.update(f"eps:{float(np.float32(fp.eps))!r}\n".encode())
    for name in FloatParams.ARRAYS:
        _feed(h, "f." + name, getattr(fp, name), "<f4")
    return h.hexdigest()


def content_hash_net(net: QNet, fn: FloatNet) -> str:
    """sha256 hex of a layer-table model's content (any architecture but SN-S, whose hash is content_hash).
    The scales s are information only and left out, so that a bundle read back from its headers hashes the same."""
    h = hashlib.sha256(CONTENT_TAG)
    sc = net.scalars()
    sc = {**sc, "blocks": [{k: v for k, v in b.items() if k != "s"} for b in sc["blocks"]]}
    sc.pop("s_out"), sc.pop("logit_scale")
    h.update(json.dumps(sc, sort_keys=True, separators=(",", ":")).encode() + b"\n")
    for k, blk in enumerate(net.blocks):
        for name in QBlock.INT_ARRAYS:
            _feed(h, f"q.{k}.{name}", getattr(blk, name), "<i8")
    _feed(h, "q.w_out", net.w_out, "<i8")
    _feed(h, "q.b_out", net.b_out, "<i8")
    _feed(h, "q.rsqrt_seed", net.rsqrt_seed, "<i8")
    h.update(f"eps:{float(np.float32(fn.eps))!r}\n".encode())
    for k, fb in enumerate(fn.blocks):
        for name in FloatBlock.ARRAYS:
            _feed(h, f"f.{k}.{name}", getattr(fb, name), "<f4")
    _feed(h, "f.w_out", fn.w_out, "<f4")
    _feed(h, "f.b_out", fn.b_out, "<f4")
    return h.hexdigest()


def hash32(hex_digest: str) -> int:
    """First 4 bytes of the digest, big-endian (what slipest_model_hash32() returns)."""
    return int(hex_digest[:8], 16)


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 16), b""):
            h.update(chunk)
    return h.hexdigest()


def file_entries(bundle: Path, names: list[str]) -> dict[str, dict[str, Any]]:
    return {n: {"sha256": file_sha256(bundle / n), "bytes": (bundle / n).stat().st_size} for n in sorted(names)}


def write_manifest(bundle: Path, manifest: dict[str, Any]) -> Path:
    path = Path(bundle) / MANIFEST
    path.write_text(json.dumps(manifest, indent=2, sort_keys=False) + "\n")
    return path


def read_manifest(bundle: Path) -> dict[str, Any]:
    path = Path(bundle) / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no manifest.json: not an export bundle")
    try:
        m = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: manifest is not valid JSON ({e})") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise ValueError(f"{path}: unknown manifest format {m.get('format') if isinstance(m, dict) else None!r}, expected {FORMAT!r}")
    for key in ("content_hash", "files", "arch"):
        if key not in m:
            raise ValueError(f"{path}: manifest has no {key!r}")
    return m


def verify_files(bundle: Path, manifest: dict[str, Any]) -> None:
    """Every file listed in the manifest exists with the recorded size and sha256."""
    bundle = Path(bundle)
    for name, entry in manifest["files"].items():
        p = bundle / name
        if not p.is_file():
            raise ValueError(f"{p}: listed in manifest.json but missing")
        size = p.stat().st_size
        if size != entry["bytes"]:
            raise ValueError(f"{p}: {size} bytes, manifest.json says {entry['bytes']} (truncated or edited)")
        if file_sha256(p) != entry["sha256"]:
            raise ValueError(f"{p}: sha256 differs from manifest.json (file edited or corrupted)")
