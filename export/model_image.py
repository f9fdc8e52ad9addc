"""model.img: the SN-S model as one self-describing, versioned binary (the run-time model format).

Layout (every multi-byte integer and float is LITTLE-ENDIAN; floats are IEEE-754 binary32 bits;
specified in docs/fixed_point.md, "Model image"):

    header   64 bytes   magic "SLPM", format version, architecture id, header size, flags, layer sizes,
                        every shift and scale of the fixed-point scheme, model version, hash32,
                        payload size (see HEADER below, zero-padded to 64 bytes)
    payload             fixed-point arrays w1 b1 gamma beta w2 b2 gelu rsqrt_seed, then (flag F32)
                        the float32 LayerNorm eps and arrays w1 b1 gamma beta w2 b2
    trailer  36 bytes   CRC-32 (IEEE 802.3, as zlib.crc32) of header + payload, then the bundle's
                        sha256 content hash (32 bytes; its first 4 bytes big-endian are hash32)
    tag      32 bytes   only with flag HMAC: HMAC-SHA256 of header + payload under the key the
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

IMAGE_FILE = "model.img"
MAGIC = b"SLPM"
FORMAT_VERSION = 1
ARCH_SN_S = 1  # 12 features -> Linear(30) -> LayerNorm -> GELU -> Linear(3), fixed-point scheme 1
HEADER_SIZE = 64
TRAILER_SIZE = 4 + 32
FLAG_F32 = 0x0001
FLAG_HMAC = 0x0002  # an HMAC-SHA256 tag over header + payload follows the trailer
HMAC_SIZE = 32
HMAC_KEY_BYTES = (16, 64)  # accepted key lengths (the C build refuses others too)
# magic, version, arch, header size, flags, n_in, n_hidden, n_out, gelu_n, rsqrt_seed_n, h_bits, e_bits,
# fz, fg, fy, gelu_step_log2, eps_e (int8), eps_m (int16), c30, eps_cap, model version, hash32, payload size
HEADER = struct.Struct("<4sHHHH11BbhiiIII")
# (QParams attribute, little-endian dtype, element count)
Q_LAYOUT = (("w1", "<i2", 360), ("b1", "<i4", 30), ("g", "<i2", 30), ("bb", "<i4", 30), ("w2", "<i2", 90),
            ("b2", "<i4", 3), ("gelu", "<i2", 129), ("rsqrt_seed", "<u4", 24))
F32_LAYOUT = (("w1", 360), ("b1", 30), ("gamma", 30), ("beta", 30), ("w2", 90), ("b2", 3))


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
    (flags,) = struct.unpack_from("<H", data, 10)
    if flags & FLAG_HMAC:
        raise ValueError("image is already signed")
    body = bytearray(data[:-TRAILER_SIZE])
    struct.pack_into("<H", body, 10, flags | FLAG_HMAC)
    body = bytes(body)
    return body + struct.pack("<I", zlib.crc32(body)) + data[-32:] + _tag(key, body)


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
    header = HEADER.pack(
        MAGIC, FORMAT_VERSION, ARCH_SN_S, HEADER_SIZE, flags, sc["n_in"], sc["n_hidden"], sc["n_out"], sc["gelu_n"],
        len(qp.rsqrt_seed), sc["h_bits"], sc["e_bits"], sc["fz"], sc["fg"], sc["fy"], sc["gelu_step_log2"],
        sc["eps_e"], sc["eps_m"], sc["c30"], sc["eps_cap"], model_version, int(content_hash[:8], 16), len(payload),
    ).ljust(HEADER_SIZE, b"\0")
    data = header + payload
    data += struct.pack("<I", zlib.crc32(data)) + bytes.fromhex(content_hash)
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
    f = HEADER.unpack_from(data, 0)
    magic, version, arch, hsize, flags = f[:5]
    if magic != MAGIC:
        raise ValueError(f"bad magic {magic!r}")
    if version != FORMAT_VERSION:
        raise ValueError(f"format version {version}, this reader knows {FORMAT_VERSION}")
    if arch != ARCH_SN_S or hsize != HEADER_SIZE:
        raise ValueError(f"architecture {arch} / header size {hsize} is not SN-S format 1")
    keys = ("n_in", "n_hidden", "n_out", "gelu_n", "rsqrt_seed_n", "h_bits", "e_bits", "fz", "fg", "fy",
            "gelu_step_log2", "eps_e", "eps_m", "c30", "eps_cap")
    scalars = dict(zip(keys, f[5:20]))
    model_version, hash32, payload_len = f[20], f[21], f[22]
    q_len = sum(np.dtype(dt).itemsize * n for _, dt, n in Q_LAYOUT)
    f_len = 4 + 4 * sum(n for _, n in F32_LAYOUT) if flags & FLAG_F32 else 0
    if flags & ~(FLAG_F32 | FLAG_HMAC):
        raise ValueError(f"unknown flags 0x{flags:04x}")
    tag_len = HMAC_SIZE if flags & FLAG_HMAC else 0
    if payload_len != q_len + f_len or len(data) != HEADER_SIZE + payload_len + TRAILER_SIZE + tag_len:
        raise ValueError(f"payload size {payload_len} / image size {len(data)} disagree with the SN-S layout")
    body_end = HEADER_SIZE + payload_len
    (crc,) = struct.unpack_from("<I", data, body_end)
    if crc != zlib.crc32(data[:body_end]):
        raise ValueError("CRC-32 mismatch")
    sha = data[body_end + 4 : body_end + 36].hex()
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
