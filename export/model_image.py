"""model.img: the SN-S model as one self-describing, versioned binary (the run-time model format).

Layout (every multi-byte integer and float is LITTLE-ENDIAN; floats are IEEE-754 binary32 bits;
specified in docs/fixed_point.md, "Model image"; every offset and size in image_layout.py, the one
description this module, the C reader and the model store are driven from):

    header              magic "SLPM", format version, architecture id, header size, flags, layer sizes,
                        every shift and scale of the fixed-point scheme, model version, hash32,
                        payload size, zero-padded to the header size
    payload             fixed-point arrays w1 b1 gamma beta w2 b2 gelu rsqrt_seed, then (flag F32)
                        the float32 LayerNorm eps and arrays w1 b1 gamma beta w2 b2
    trailer             CRC-32 (IEEE 802.3, as zlib.crc32) of header + payload, then the bundle's
                        sha256 content hash (its first 4 bytes big-endian are hash32)
    tag                 only with flag HMAC: HMAC-SHA256 of header + payload under the key the
                        flight build was provisioned with (firmware_c/src/slipest_store.c checks it)

One writer (here) and one validating C reader (firmware_c/src/slipest_image.c). `read_image` is the
Python reader used by tests and `fleetlab export --check-only`; it checks what the C reader checks.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .quant import FloatParams, QParams

from . import image_layout as layout

IMAGE_FILE = "model.img"
# the layout's facts, under the names the rest of the toolchain imports (one source: image_layout.py)
MAGIC, ARCH_SN_S, FLAG_F32, FLAG_HMAC, HMAC_SIZE = (layout.MAGIC, layout.ARCH_SN_S, layout.FLAG_F32, layout.FLAG_HMAC,
                                                    layout.HMAC_SIZE)
FORMAT_VERSION = layout.CURRENT.version
HEADER_SIZE = layout.CURRENT.header_size
TRAILER_SIZE = layout.CURRENT.trailer_size
HMAC_KEY_BYTES = (16, 64)  # accepted key lengths (the C build refuses others too)
HEADER = layout.CURRENT.header_struct
# (QParams attribute, little-endian dtype, element count)
Q_LAYOUT = tuple((a.name, a.dtype, a.count) for a in layout.CURRENT.q_arrays)
F32_LAYOUT = tuple((a.name, a.count) for a in layout.CURRENT.f32_arrays)
_SCALARS = ("n_in", "n_hidden", "n_out", "gelu_n", "rsqrt_seed_n", "h_bits", "e_bits", "fz", "fg", "fy",
            "gelu_step_log2", "eps_e", "eps_m", "c30", "eps_cap")


@dataclass
class ModelImage:
    qparams_arrays: dict[str, np.ndarray]
    scalars: dict[str, int]
    fparams: FloatParams | None
    model_version: int
    content_hash: str


def check_hmac_key(key: bytes) -> bytes:
    if not HMAC_KEY_BYTES[0] <= len(key) <= HMAC_KEY_BYTES[1]:
        raise ValueError(f"HMAC key of {len(key)} bytes; give {HMAC_KEY_BYTES[0]}..{HMAC_KEY_BYTES[1]} random bytes")
    return key


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(check_hmac_key(key), body, hashlib.sha256).digest()


def sign_image(data: bytes, key: bytes) -> bytes:
    """An unsigned image with flag HMAC set, its CRC redone and the tag appended."""
    read_image(data)  # only a valid image is signed
    flags = int(layout.header_fields(data)["flags"])
    if flags & FLAG_HMAC:
        raise ValueError("image is already signed")
    flagged = layout.patch_header(data, seal=False, flags=flags | FLAG_HMAC)
    return layout.reseal(flagged + bytes(HMAC_SIZE), key=check_hmac_key(key))  # room for the tag, then sealed


def image_bytes(qp: QParams, fp: FloatParams | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> bytes:
    """The image of a quantised model (and its float model when fp is given), signed when hmac_key is given."""
    if not 1 <= model_version < 2**31:
        raise ValueError(f"model version {model_version} outside 1 .. 2^31 - 1")
    sc = qp.scalars()
    payload = b"".join(np.ascontiguousarray(np.asarray(getattr(qp, a)).reshape(-1).astype(dt)).tobytes()
                       for a, dt, _ in Q_LAYOUT)
    flags = 0
    if fp is not None:
        flags |= FLAG_F32
        payload += struct.pack("<f", float(np.float32(fp.eps)))
        payload += b"".join(np.asarray(getattr(fp, a), dtype="<f4").reshape(-1).tobytes() for a, _ in F32_LAYOUT)
    fields = {**{k: sc[k] for k in _SCALARS if k != "rsqrt_seed_n"}, "rsqrt_seed_n": len(qp.rsqrt_seed),
              "magic": MAGIC, "format": FORMAT_VERSION, "arch": ARCH_SN_S, "header_size": HEADER_SIZE,
              "flags": flags, "model_version": model_version, "hash32": int(content_hash[:8], 16),
              "payload_size": len(payload)}
    header = HEADER.pack(*(fields[f.name] for f in layout.CURRENT.header)).ljust(HEADER_SIZE, b"\0")
    data = header + payload
    data += layout.CURRENT.trailer_struct.pack(zlib.crc32(data), bytes.fromhex(content_hash))
    return sign_image(data, hmac_key) if hmac_key is not None else data


def write_image(out_dir: Path, qp: QParams, fp: FloatParams | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> Path:
    path = Path(out_dir) / IMAGE_FILE
    path.write_bytes(image_bytes(qp, fp, content_hash, model_version, hmac_key))
    return path


def read_image(data: bytes, hmac_key: bytes | None = None) -> ModelImage:
    """Parse and validate an image; ValueError names the first problem found. With hmac_key the image must
    carry a tag that verifies under it (without, a tag is length-checked only, as the C reader does)."""
    if len(data) < HEADER_SIZE + TRAILER_SIZE:
        raise ValueError(f"image of {len(data)} bytes is shorter than header + trailer")
    f = layout.header_fields(data)
    magic, version, arch, hsize, flags = f["magic"], f["format"], f["arch"], f["header_size"], f["flags"]
    if magic != MAGIC:
        raise ValueError(f"bad magic {magic!r}")
    if version != FORMAT_VERSION:
        raise ValueError(f"format version {version}, this reader knows {FORMAT_VERSION}")
    if arch != ARCH_SN_S or hsize != HEADER_SIZE:
        raise ValueError(f"architecture {arch} / header size {hsize} is not SN-S format 1")
    scalars = {k: f[k] for k in _SCALARS}
    model_version, hash32, payload_len = f["model_version"], f["hash32"], f["payload_size"]
    q_len = layout.CURRENT.q_payload_size
    f_len = layout.CURRENT.f32_payload_size if flags & FLAG_F32 else 0
    if flags & ~(FLAG_F32 | FLAG_HMAC):
        raise ValueError(f"unknown flags 0x{flags:04x}")
    tag_len = HMAC_SIZE if flags & FLAG_HMAC else 0
    if payload_len != q_len + f_len or len(data) != HEADER_SIZE + payload_len + TRAILER_SIZE + tag_len:
        raise ValueError(f"payload size {payload_len} / image size {len(data)} disagree with the SN-S layout")
    body_end = HEADER_SIZE + payload_len
    crc, sha_bytes = layout.CURRENT.trailer_struct.unpack_from(data, body_end)
    if crc != zlib.crc32(data[:body_end]):
        raise ValueError("CRC-32 mismatch")
    sha = sha_bytes.hex()
    if int(sha[:8], 16) != hash32:
        raise ValueError("hash32 in the header is not the start of the trailer's sha256")
    if hmac_key is not None:
        if not flags & FLAG_HMAC:
            raise ValueError("HMAC: the image carries no tag")
        if not hmac.compare_digest(_tag(hmac_key, data[:body_end]), data[body_end + TRAILER_SIZE:]):
            raise ValueError("HMAC: the tag does not verify under this key")
    off, arrays = HEADER_SIZE, {}
    for name, dt, n in Q_LAYOUT:
        arrays[name] = np.frombuffer(data, dtype=dt, count=n, offset=off).astype(np.dtype(dt).newbyteorder("="))
        off += np.dtype(dt).itemsize * n
    fp = None
    if flags & FLAG_F32:
        (eps,) = struct.unpack_from("<f", data, off)
        off += 4
        fa = {}
        for name, n in F32_LAYOUT:
            fa[name] = np.frombuffer(data, dtype="<f4", count=n, offset=off).astype(np.float32)
            off += 4 * n
        fa["w1"], fa["w2"] = fa["w1"].reshape(30, 12), fa["w2"].reshape(3, 30)
        fp = FloatParams(**fa, eps=float(np.float32(eps)))
    arrays["w1"], arrays["w2"] = arrays["w1"].reshape(30, 12), arrays["w2"].reshape(3, 30)
    return ModelImage(arrays, scalars, fp, model_version, sha)
