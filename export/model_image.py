"""model.img: a model as one self-describing, versioned binary (the run-time model format).

One writer and one reader for every format: an SN-S is written in format 1 (the format every C reader of a
rover reads, and the model store keeps), any other network in format 2 (a layer table in its header);
`read_image` reads both. Both formats are one description, image_layout.py: format 1 is a profile of the
layer-table layout (widths fixed to (30,), the block's fields in the header, no table).

Layout (every multi-byte integer and float is LITTLE-ENDIAN; floats are IEEE-754 binary32 bits;
specified in docs/fixed_point.md, "Model image"; every offset and size in image_layout.py, the one
description this module, the C reader and the model store are driven from):

    header              magic "SLPM", format version, architecture id, header size, flags, layer sizes,
                        every shift and scale of the fixed-point scheme (format 2: per block, in the layer
                        table), model version, hash32, payload size, zero-padded to the header size
    payload             the fixed-point arrays (per block, then the head), then (flag F32) the float32
                        LayerNorm eps and the float arrays
    trailer             CRC-32 (IEEE 802.3, as zlib.crc32) of header + payload, then the bundle's
                        sha256 content hash (its first 4 bytes big-endian are hash32)
    tag                 only with flag HMAC: HMAC-SHA256 of header + payload under the key the
                        flight build was provisioned with (firmware_c/src/slipest_store.c checks it)

One writer (here) and one validating C reader (firmware_c/src/slipest_image_stream.c and its format visitors). `read_image` is the
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

from . import image_layout as layout
from . import quant
from .quant import FloatBlock, FloatNet, QBlock, QNet
from fleetlab.errors import InputError

IMAGE_FILE = "model.img"
# the layout's facts, under the names the rest of the toolchain imports (one source: image_layout.py)
MAGIC, ARCH_SN_S, FLAG_F32, FLAG_HMAC, HMAC_SIZE = (layout.MAGIC, layout.ARCH_SN_S, layout.FLAG_F32, layout.FLAG_HMAC,
                                                    layout.HMAC_SIZE)
FORMAT_VERSION = layout.CURRENT.version
HEADER_SIZE = layout.CURRENT.header_size
TRAILER_SIZE = layout.CURRENT.trailer_size
HMAC_KEY_BYTES = (16, 64)  # accepted key lengths (the C build refuses others too)


@dataclass
class ModelImage:
    qnet: QNet  # the fixed-point model; its scales s are NaN (an image does not store them)
    fnet: FloatNet | None  # the float model (flag F32)
    header: dict[str, object]  # the header fields by name (format 1: every scalar of the scheme)
    model_version: int
    content_hash: str
    format_version: int = FORMAT_VERSION


def check_hmac_key(key: bytes) -> bytes:
    if not HMAC_KEY_BYTES[0] <= len(key) <= HMAC_KEY_BYTES[1]:
        raise InputError(f"HMAC key of {len(key)} bytes; give {HMAC_KEY_BYTES[0]}..{HMAC_KEY_BYTES[1]} random bytes")
    return key


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(check_hmac_key(key), body, hashlib.sha256).digest()


def sign_image(data: bytes, key: bytes) -> bytes:
    """An unsigned image with flag HMAC set, its CRC redone and the tag appended."""
    read_image(data)  # only a valid image is signed
    flags = int(layout.header_fields(data)["flags"])
    if flags & FLAG_HMAC:
        raise InputError("image is already signed")
    flagged = layout.patch_header(data, seal=False, flags=flags | FLAG_HMAC)
    return layout.reseal(flagged + bytes(HMAC_SIZE), key=check_hmac_key(key))  # room for the tag, then sealed


def _le(arr, dtype: str, count: int) -> bytes:
    flat = np.ascontiguousarray(np.asarray(arr).reshape(-1).astype(dtype))
    if flat.size != count:
        raise InputError(f"array of {flat.size} elements where the layout has {count}")
    return flat.tobytes()


def _arrays_bytes(net: QNet | FloatNet, arrays: list[tuple[int | None, layout.Array]]) -> bytes:
    """The arrays in payload order: a block's (index i) or the network's own (None)."""
    return b"".join(_le(getattr(net if i is None else net.blocks[i], a.name), a.dtype, a.count) for i, a in arrays)


def _record(blk: QBlock) -> dict[str, int]:
    """A block's layer-table record (format 1: its header fields) by record field name."""
    return {**blk.scalars(), "width": blk.width}


def image_bytes(qn: QNet, fn: FloatNet | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> bytes:
    """The image of a quantised model (and its float model when fn is given), signed when hmac_key is given:
    format 1 for an SN-S, format 2 for any other network."""
    if not 1 <= model_version < 2**31:
        raise InputError(f"model version {model_version} outside 1 .. 2^31 - 1")
    L = layout.layout_for(qn.hidden)
    qn.check_bounds()
    payload = _arrays_bytes(qn, L.q_arrays_for(qn.hidden))
    flags = 0
    if fn is not None:
        if fn.hidden != qn.hidden:
            raise InputError(f"float model {list(fn.hidden)} and fixed-point model {list(qn.hidden)} differ")
        flags |= FLAG_F32
        payload += struct.pack("<f", float(np.float32(fn.eps))) + _arrays_bytes(fn, L.f32_arrays_for(fn.hidden))
    fields = {"magic": MAGIC, "format": L.version, "arch": L.arch, "header_size": L.header_size, "flags": flags,
              "n_in": layout.N_IN, "n_out": layout.N_OUT, "n_layers": len(qn.blocks), "gelu_n": layout.GELU_N,
              "rsqrt_seed_n": len(qn.rsqrt_seed), "gelu_step_log2": quant.GELU_STEP_LOG2, "eps_cap": quant.EPS_CAP,
              "model_version": model_version, "hash32": int(content_hash[:8], 16), "payload_size": len(payload)}
    data = L.pack_header(fields, [_record(b) for b in qn.blocks]) + payload
    data += L.trailer_struct.pack(zlib.crc32(data), bytes.fromhex(content_hash))
    return sign_image(data, hmac_key) if hmac_key is not None else data


def write_image(out_dir: Path, qn: QNet, fn: FloatNet | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> Path:
    path = Path(out_dir) / IMAGE_FILE
    path.write_bytes(image_bytes(qn, fn, content_hash, model_version, hmac_key))
    return path


def _check_reserved(data: bytes, L: layout.ImageLayout, n_layers: int) -> None:
    """Reserved header bytes, record padding and unused records are zero."""
    if L.table_at is None:
        if any(data[L.reserved_start:L.header_size]):
            raise InputError("reserved header bytes are not zero")
        return
    if any(data[L.reserved_start:L.table_at]):
        raise InputError("reserved header bytes are not zero")
    for i in range(L.max_layers):
        start = L.table_at + i * L.record_size + (L.record_struct.size if i < n_layers else 0)
        if any(data[start:L.table_at + (i + 1) * L.record_size]):
            raise InputError(f"layer-table record {i + 1}: reserved bytes are not zero")
    if any(data[L.table_at + L.max_layers * L.record_size:L.header_size]):
        raise InputError("reserved header bytes are not zero")


def _check_frame(data: bytes, L: layout.ImageLayout, flags: int, payload_len: int, want: int,
                 hmac_key: bytes | None) -> tuple[int, str]:
    """The checks every format shares (flags, sizes, CRC, hash32, HMAC); returns (body end, sha256 hex)."""
    if flags & ~(FLAG_F32 | FLAG_HMAC):
        raise InputError(f"unknown flags 0x{flags:04x}")
    tag_len = HMAC_SIZE if flags & FLAG_HMAC else 0
    if payload_len != want or len(data) != L.header_size + payload_len + L.trailer_size + tag_len:
        raise InputError(f"payload size {payload_len} / image size {len(data)} disagree with the format-{L.version} "
                         f"layout ({want} payload bytes)")
    body_end = L.header_size + payload_len
    crc, sha_bytes = L.trailer_struct.unpack_from(data, body_end)
    if crc != zlib.crc32(data[:body_end]):
        raise InputError("CRC-32 mismatch")
    sha = sha_bytes.hex()
    if int(sha[:8], 16) != int(layout.header_fields(data, L)["hash32"]):
        raise InputError("hash32 in the header is not the start of the trailer's sha256")
    if hmac_key is not None:
        if not flags & FLAG_HMAC:
            raise InputError("HMAC: the image carries no tag")
        if not hmac.compare_digest(_tag(hmac_key, data[:body_end]), data[body_end + L.trailer_size:]):
            raise InputError("HMAC: the tag does not verify under this key")
    return body_end, sha


def _array(data: bytes, a: layout.Array, off: int) -> np.ndarray:
    return np.frombuffer(data, dtype=a.dtype, count=int(a.count), offset=off).astype(np.dtype(a.dtype).newbyteorder("="))


def _read_arrays(data: bytes, arrays: list[tuple[int | None, layout.Array]], off: int,
                 n_blocks: int) -> tuple[list[dict[str, np.ndarray]], dict[str, np.ndarray], int]:
    """(per block arrays by name, the network's own, the offset after them)."""
    blocks: list[dict[str, np.ndarray]] = [dict() for _ in range(n_blocks)]
    own: dict[str, np.ndarray] = {}
    for i, a in arrays:
        (own if i is None else blocks[i])[a.name] = _array(data, a, off)
        off += a.size
    return blocks, own, off


def _widths(L: layout.ImageLayout, recs: list[dict[str, object]]) -> tuple[int, ...]:
    widths = tuple(int(r["width"]) for r in recs)
    if L.widths is not None and widths != L.widths:
        raise InputError(f"layer widths {list(widths)} are not format {L.version}'s {list(L.widths)}")
    if any(not 2 <= w <= layout.MAX_WIDTH for w in widths):
        raise InputError(f"layer widths {list(widths)} outside 2 .. {layout.MAX_WIDTH}")
    return widths


def read_image(data: bytes, hmac_key: bytes | None = None) -> ModelImage:
    """Parse and validate an image of any known format; ValueError names the first problem found (an
    unknown format names its version). With hmac_key the image must carry a tag that verifies under it
    (without, a tag is length-checked only, as the C reader does)."""
    if len(data) < HEADER_SIZE + TRAILER_SIZE:
        raise InputError(f"image of {len(data)} bytes is shorter than header + trailer")
    if data[:4] != MAGIC:
        raise InputError(f"bad magic {data[:4]!r}")
    L = layout.layout_of(data)
    if len(data) < L.header_size + L.trailer_size:
        raise InputError(f"image of {len(data)} bytes is shorter than header + trailer")
    f = layout.header_fields(data, L)
    if f["arch"] != L.arch or f["header_size"] != L.header_size:
        raise InputError(f"architecture {f['arch']} / header size {f['header_size']} is not format {L.version}'s")
    if (f["n_in"], f["n_out"], f["gelu_n"], f["rsqrt_seed_n"]) != (layout.N_IN, layout.N_OUT, layout.GELU_N,
                                                                     layout.RSQRT_SEED_N):
        raise InputError("inputs, classes or table sizes differ from scheme 1")
    recs = layout.layer_records(data, L)
    widths = _widths(L, recs)
    _check_reserved(data, L, len(recs))
    flags = int(f["flags"])
    want = L.q_payload_size(widths) + (L.f32_payload_size(widths) if flags & FLAG_F32 else 0)
    _, sha = _check_frame(data, L, flags, int(f["payload_size"]), want, hmac_key)
    blocks, own, off = _read_arrays(data, L.q_arrays_for(widths), L.header_size, len(widths))
    n_in, qblocks = layout.N_IN, []
    for r, arr in zip(recs, blocks):
        w = int(r["width"])
        qblocks.append(QBlock(w=arr["w"].reshape(w, n_in), b=arr["b"], g=arr["g"], bb=arr["bb"], gelu=arr["gelu"],
                              fg=int(r["fg"]), fy=int(r["fy"]), eps_m=int(r["eps_m"]), eps_e=int(r["eps_e"]),
                              s=float("nan")))
        n_in = w
    qn = QNet(qblocks, own["w_out"].reshape(layout.N_OUT, n_in), own["b_out"], float("nan"),
              own["rsqrt_seed"].astype(np.int64))
    for blk, r in zip(qblocks, recs):  # the derived shifts in the table must be the scheme's for the width
        derived = {"h_bits": blk.h_bits, "e_bits": blk.e_bits, "fz": blk.fz, "c": blk.c}
        if any(int(r[k]) != v for k, v in derived.items()):
            raise InputError(f"layer of width {blk.width}: shifts {({k: r[k] for k in derived})} are not the scheme's")
    qn.check_bounds()
    fn = None
    if flags & FLAG_F32:
        (eps,) = struct.unpack_from("<f", data, off)
        fblocks, fown, _ = _read_arrays(data, L.f32_arrays_for(widths), off + 4, len(widths))
        n_in, fbl = layout.N_IN, []
        for w, arr in zip(widths, fblocks):
            fbl.append(FloatBlock(arr["w"].reshape(w, n_in), arr["b"], arr["gamma"], arr["beta"]))
            n_in = w
        fn = FloatNet(fbl, fown["w_out"].reshape(layout.N_OUT, n_in), fown["b_out"], float(np.float32(eps)))
    return ModelImage(qn, fn, f, int(f["model_version"]), sha, L.version)


def same_model(img: ModelImage, qn: QNet) -> bool:
    """Whether an image holds exactly these fixed-point parameters (every block's arrays and shifts)."""
    got = img.qnet
    if got.hidden != qn.hidden:
        return False
    same = all(np.array_equal(np.asarray(getattr(a, k)), np.asarray(getattr(b, k))) and (a.fg, a.fy, a.eps_m, a.eps_e)
               == (b.fg, b.fy, b.eps_m, b.eps_e) for a, b in zip(got.blocks, qn.blocks) for k in QBlock.INT_ARRAYS)
    return same and all(np.array_equal(np.asarray(getattr(got, k)), np.asarray(getattr(qn, k)))
                        for k in ("w_out", "b_out", "rsqrt_seed"))
