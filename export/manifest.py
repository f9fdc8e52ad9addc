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

from . import sns_profile
from .quant import FloatBlock, FloatNet, QBlock, QNet
from fleetlab.errors import InputError

MANIFEST = "manifest.json"
FORMAT = "fleetlab-bundle/1"
CONTENT_TAG = b"fleetlab-slipest-model/1\n"


def _feed(h, name: str, arr: np.ndarray, dtype: str) -> None:
    a = np.ascontiguousarray(np.asarray(arr).astype(dtype))
    h.update(f"{name}:{a.dtype.str}:{list(a.shape)}\n".encode())
    h.update(a.tobytes())


def quantization_scalars(net: QNet) -> dict:
    """The scheme's scalars a bundle records (manifest.json `quantization`): an SN-S's flat dict (the SN-S
    formats name them so), any other network's list of blocks."""
    return sns_profile.scalars(net) if sns_profile.fits(net) else net.scalars()


def _named_arrays(net: QNet, fn: FloatNet) -> tuple[dict, list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """(scalars, integer arrays, float arrays) that the content hash covers, under the names it has always used:
    an SN-S's flat ones, else per block. A layer-table model's scales s are information only and left out, so that
    a bundle read back from its headers hashes the same (an SN-S's s1 and s2 were hashed from the start, and
    its loader takes them from the manifest)."""
    if sns_profile.fits(net):
        return (sns_profile.scalars(net), list(sns_profile.q_arrays(net).items()),
                list(sns_profile.f32_arrays(fn).items()))
    sc = net.scalars()
    sc = {**sc, "blocks": [{k: v for k, v in b.items() if k != "s"} for b in sc["blocks"]]}
    sc.pop("s_out"), sc.pop("logit_scale")
    q = [(f"{k}.{name}", getattr(blk, name)) for k, blk in enumerate(net.blocks) for name in QBlock.INT_ARRAYS]
    q += [(name, getattr(net, name)) for name in ("w_out", "b_out", "rsqrt_seed")]
    f = [(f"{k}.{name}", getattr(fb, name)) for k, fb in enumerate(fn.blocks) for name in FloatBlock.ARRAYS]
    f += [(name, getattr(fn, name)) for name in ("w_out", "b_out")]
    return sc, q, f


def content_hash(net: QNet, fn: FloatNet) -> str:
    """sha256 hex of the canonical model content: the scheme's scalars (JSON, sorted keys), each integer array
    (int64) and, after the float LayerNorm eps, each float32 array, every array preceded by its name."""
    sc, q, f = _named_arrays(net, fn)
    h = hashlib.sha256(CONTENT_TAG)
    h.update(json.dumps(sc, sort_keys=True, separators=(",", ":")).encode() + b"\n")
    for name, arr in q:
        _feed(h, "q." + name, arr, "<i8")
    h.update(f"eps:{float(np.float32(fn.eps))!r}\n".encode())
    for name, arr in f:
        _feed(h, "f." + name, arr, "<f4")
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
        raise InputError(f"{path}: manifest is not valid JSON ({e})") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise InputError(f"{path}: unknown manifest format {m.get('format') if isinstance(m, dict) else None!r}, expected {FORMAT!r}")
    for key in ("content_hash", "files", "arch"):
        if key not in m:
            raise InputError(f"{path}: manifest has no {key!r}")
    return m


def verify_files(bundle: Path, manifest: dict[str, Any]) -> None:
    """Every file listed in the manifest exists with the recorded size and sha256."""
    bundle = Path(bundle)
    for name, entry in manifest["files"].items():
        p = bundle / name
        if not p.is_file():
            raise InputError(f"{p}: listed in manifest.json but missing")
        size = p.stat().st_size
        if size != entry["bytes"]:
            raise InputError(f"{p}: {size} bytes, manifest.json says {entry['bytes']} (truncated or edited)")
        if file_sha256(p) != entry["sha256"]:
            raise InputError(f"{p}: sha256 differs from manifest.json (file edited or corrupted)")
