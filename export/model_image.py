"""model.img: a model as one self-describing, versioned binary (the run-time model format).

Format 1 carries an SN-S; format 2 any architecture (a layer table in its header). The writer gives an
SN-S (QParams) format 1, which the C reader and the model store read, and any other architecture (QNet)
format 2; `read_image` reads both.

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

from .quant import FloatBlock, FloatNet, FloatParams, QBlock, QNet, QParams

from . import image_layout as layout
from . import quant

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
    qparams_arrays: dict[str, np.ndarray]  # format 1: the QParams arrays by name; format 2: empty
    scalars: dict[str, int]
    fparams: FloatParams | FloatNet | None
    model_version: int
    content_hash: str
    format_version: int = FORMAT_VERSION
    qnet: QNet | None = None  # the fixed-point model as blocks (both formats); its scales s are NaN (not stored)


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


def _le(arr, dtype: str, count: int) -> bytes:
    flat = np.ascontiguousarray(np.asarray(arr).reshape(-1).astype(dtype))
    if flat.size != count:
        raise ValueError(f"array of {flat.size} elements where the layout has {count}")
    return flat.tobytes()


def _seal(header: bytes, payload: bytes, layout_: layout.Layout | layout.TableLayout, content_hash: str,
          hmac_key: bytes | None) -> bytes:
    data = header.ljust(layout_.header_size, b"\0") + payload
    data += layout_.trailer_struct.pack(zlib.crc32(data), bytes.fromhex(content_hash))
    return sign_image(data, hmac_key) if hmac_key is not None else data


def _net_image(qn: QNet, fn: FloatNet | None, content_hash: str, model_version: int,
               hmac_key: bytes | None) -> bytes:
    """Format 2: the layer table in the header, the blocks' arrays in the payload (image_layout.V2)."""
    L = layout.V2
    qn.check_bounds()
    blocks = {i: b for i, b in enumerate(qn.blocks)}
    head = {"w_out": qn.w_out, "b_out": qn.b_out, "rsqrt_seed": qn.rsqrt_seed}
    payload = b"".join(_le(getattr(blocks[i], a.name) if i is not None else head[a.name], a.dtype, a.count)
                       for i, a in L.q_arrays_for(qn.hidden))
    flags = 0
    if fn is not None:
        if fn.hidden != qn.hidden:
            raise ValueError(f"float model {list(fn.hidden)} and fixed-point model {list(qn.hidden)} differ")
        flags |= FLAG_F32
        fblocks = dict(enumerate(fn.blocks))
        fhead = {"w_out": fn.w_out, "b_out": fn.b_out}
        payload += struct.pack("<f", float(np.float32(fn.eps)))
        payload += b"".join(_le(getattr(fblocks[i], a.name) if i is not None else fhead[a.name], a.dtype, a.count)
                            for i, a in L.f32_arrays_for(fn.hidden))
    fields = {"magic": MAGIC, "format": L.version, "arch": layout.ARCH_TABLE, "header_size": L.header_size,
              "flags": flags, "n_in": layout.N_IN, "n_out": layout.N_OUT, "n_layers": len(qn.blocks),
              "gelu_n": layout.GELU_N, "rsqrt_seed_n": len(qn.rsqrt_seed), "gelu_step_log2": quant.GELU_STEP_LOG2,
              "eps_cap": quant.EPS_CAP, "model_version": model_version, "hash32": int(content_hash[:8], 16),
              "payload_size": len(payload)}
    header = bytearray(L.header_struct.pack(*(fields[f.name] for f in L.header)).ljust(L.header_size, b"\0"))
    for i, b in enumerate(qn.blocks):
        rec = {**b.scalars(), "width": b.width}
        L.record_struct.pack_into(header, L.table_at + i * L.record_size, *(rec[f.name] for f in L.record))
    return _seal(bytes(header), payload, L, content_hash, hmac_key)


def image_bytes(qp: QParams | QNet, fp: FloatParams | FloatNet | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> bytes:
    """The image of a quantised model (and its float model when fp is given), signed when hmac_key is given:
    format 1 for an SN-S (QParams), format 2 for any architecture (QNet)."""
    if not 1 <= model_version < 2**31:
        raise ValueError(f"model version {model_version} outside 1 .. 2^31 - 1")
    if isinstance(qp, QNet):
        if fp is not None and not isinstance(fp, FloatNet):
            fp = fp.net()
        return _net_image(qp, fp, content_hash, model_version, hmac_key)
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
    return _seal(HEADER.pack(*(fields[f.name] for f in layout.CURRENT.header)), payload, layout.CURRENT,
                 content_hash, hmac_key)


def write_image(out_dir: Path, qp: QParams | QNet, fp: FloatParams | FloatNet | None, content_hash: str, model_version: int = 1,
                hmac_key: bytes | None = None) -> Path:
    path = Path(out_dir) / IMAGE_FILE
    path.write_bytes(image_bytes(qp, fp, content_hash, model_version, hmac_key))
    return path


def _check_frame(data: bytes, L: layout.Layout | layout.TableLayout, flags: int, payload_len: int, want: int,
                 hmac_key: bytes | None) -> tuple[int, str]:
    """The checks every format shares (flags, sizes, CRC, hash32, HMAC); returns (body end, sha256 hex)."""
    if flags & ~(FLAG_F32 | FLAG_HMAC):
        raise ValueError(f"unknown flags 0x{flags:04x}")
    if any(data[L.reserved_start:L.header_size if not isinstance(L, layout.TableLayout) else L.table_at]):
        raise ValueError("reserved header bytes are not zero")
    tag_len = HMAC_SIZE if flags & FLAG_HMAC else 0
    if payload_len != want or len(data) != L.header_size + payload_len + L.trailer_size + tag_len:
        raise ValueError(f"payload size {payload_len} / image size {len(data)} disagree with the format-{L.version} "
                         f"layout ({want} payload bytes)")
    body_end = L.header_size + payload_len
    crc, sha_bytes = L.trailer_struct.unpack_from(data, body_end)
    if crc != zlib.crc32(data[:body_end]):
        raise ValueError("CRC-32 mismatch")
    sha = sha_bytes.hex()
    if int(sha[:8], 16) != int(layout.header_fields(data, L)["hash32"]):
        raise ValueError("hash32 in the header is not the start of the trailer's sha256")
    if hmac_key is not None:
        if not flags & FLAG_HMAC:
            raise ValueError("HMAC: the image carries no tag")
        if not hmac.compare_digest(_tag(hmac_key, data[:body_end]), data[body_end + L.trailer_size:]):
            raise ValueError("HMAC: the tag does not verify under this key")
    return body_end, sha


def _array(data: bytes, a: layout.Array, off: int) -> np.ndarray:
    return np.frombuffer(data, dtype=a.dtype, count=a.count, offset=off).astype(np.dtype(a.dtype).newbyteorder("="))


def _read_v2(data: bytes, hmac_key: bytes | None) -> ModelImage:
    L = layout.V2
    f = layout.header_fields(data, L)
    if f["arch"] != layout.ARCH_TABLE or f["header_size"] != L.header_size:
        raise ValueError(f"architecture {f['arch']} / header size {f['header_size']} is not format 2's layer table")
    if (f["n_in"], f["n_out"], f["gelu_n"], f["rsqrt_seed_n"]) != (layout.N_IN, layout.N_OUT, layout.GELU_N,
                                                                     layout.RSQRT_SEED_N):
        raise ValueError("inputs, classes or table sizes differ from scheme 1")
    recs = layout.layer_records(data, L)
    widths = tuple(int(r["width"]) for r in recs)
    if any(not 2 <= w <= layout.MAX_WIDTH for w in widths):
        raise ValueError(f"layer widths {list(widths)} outside 2 .. {layout.MAX_WIDTH}")
    for i in range(L.max_layers):  # record padding and unused records are zero
        start = L.table_at + i * L.record_size + (L.record_struct.size if i < len(recs) else 0)
        if any(data[start:L.table_at + (i + 1) * L.record_size]):
            raise ValueError(f"layer-table record {i + 1}: reserved bytes are not zero")
    if any(data[L.table_at + L.max_layers * L.record_size:L.header_size]):
        raise ValueError("reserved header bytes are not zero")
    flags = int(f["flags"])
    want = L.q_payload_size(widths) + (L.f32_payload_size(widths) if flags & FLAG_F32 else 0)
    _, sha = _check_frame(data, L, flags, int(f["payload_size"]), want, hmac_key)
    off, blocks, head = L.header_size, [dict() for _ in widths], {}
    for i, a in L.q_arrays_for(widths):
        (blocks[i] if i is not None else head)[a.name] = _array(data, a, off)
        off += a.size
    n_in, qblocks = layout.N_IN, []
    for r, arr in zip(recs, blocks):
        w = int(r["width"])
        qblocks.append(QBlock(w=arr["w"].reshape(w, n_in), b=arr["b"], g=arr["g"], bb=arr["bb"], gelu=arr["gelu"],
                              fg=int(r["fg"]), fy=int(r["fy"]), eps_m=int(r["eps_m"]), eps_e=int(r["eps_e"]),
                              s=float("nan")))
        n_in = w
    qn = QNet(qblocks, head["w_out"].reshape(layout.N_OUT, n_in), head["b_out"], float("nan"),
              head["rsqrt_seed"].astype(np.int64))
    for blk, r in zip(qblocks, recs):  # the derived shifts in the table must be the scheme's for the width
        derived = {"h_bits": blk.h_bits, "e_bits": blk.e_bits, "fz": blk.fz, "c": blk.c}
        if any(int(r[k]) != v for k, v in derived.items()):
            raise ValueError(f"layer of width {blk.width}: shifts {({k: r[k] for k in derived})} are not the scheme's")
    qn.check_bounds()
    fn = None
    if flags & FLAG_F32:
        (eps,) = struct.unpack_from("<f", data, off)
        off += 4
        fblocks, fhead = [dict() for _ in widths], {}
        for i, a in L.f32_arrays_for(widths):
            (fblocks[i] if i is not None else fhead)[a.name] = _array(data, a, off).astype(np.float32)
            off += a.size
        n_in, fbl = layout.N_IN, []
        for w, arr in zip(widths, fblocks):
            fbl.append(FloatBlock(arr["w"].reshape(w, n_in), arr["b"], arr["gamma"], arr["beta"]))
            n_in = w
        fn = FloatNet(fbl, fhead["w_out"].reshape(layout.N_OUT, n_in), fhead["b_out"], float(np.float32(eps)))
    scalars = {k: int(f[k]) for k in ("n_in", "n_out", "n_layers", "gelu_n", "rsqrt_seed_n", "gelu_step_log2",
                                      "eps_cap")}
    return ModelImage({}, scalars, fn, int(f["model_version"]), sha, L.version, qn)


def read_image(data: bytes, hmac_key: bytes | None = None) -> ModelImage:
    """Parse and validate an image of any known format; ValueError names the first problem found (an
    unknown format names its version). With hmac_key the image must carry a tag that verifies under it
    (without, a tag is length-checked only, as the C reader does)."""
    if len(data) < HEADER_SIZE + TRAILER_SIZE:
        raise ValueError(f"image of {len(data)} bytes is shorter than header + trailer")
    if data[:4] != MAGIC:
        raise ValueError(f"bad magic {data[:4]!r}")
    L = layout.layout_of(data)
    if len(data) < L.header_size + L.trailer_size:
        raise ValueError(f"image of {len(data)} bytes is shorter than header + trailer")
    if isinstance(L, layout.TableLayout):
        return _read_v2(data, hmac_key)
    f = layout.header_fields(data, L)
    arch, hsize, flags = f["arch"], f["header_size"], int(f["flags"])
    if arch != ARCH_SN_S or hsize != HEADER_SIZE:
        raise ValueError(f"architecture {arch} / header size {hsize} is not SN-S format 1")
    scalars = {k: f[k] for k in _SCALARS}
    want = L.q_payload_size + (L.f32_payload_size if flags & FLAG_F32 else 0)
    _, sha = _check_frame(data, L, flags, int(f["payload_size"]), want, hmac_key)
    off, arrays = HEADER_SIZE, {}
    for a in L.q_arrays:
        arrays[a.name] = _array(data, a, off)
        off += a.size
    fp = None
    if flags & FLAG_F32:
        (eps,) = struct.unpack_from("<f", data, off)
        off += 4
        fa = {}
        for a in L.f32_arrays:
            fa[a.name] = _array(data, a, off).astype(np.float32)
            off += a.size
        fa["w1"], fa["w2"] = fa["w1"].reshape(30, 12), fa["w2"].reshape(3, 30)
        fp = FloatParams(**fa, eps=float(np.float32(eps)))
    arrays["w1"], arrays["w2"] = arrays["w1"].reshape(30, 12), arrays["w2"].reshape(3, 30)
    qp = QParams(**{k: arrays[k] for k in QParams.INT_ARRAYS if k != "rsqrt_seed"},
                 rsqrt_seed=arrays["rsqrt_seed"].astype(np.int64), fg=int(f["fg"]), fy=int(f["fy"]),
                 eps_m=int(f["eps_m"]), eps_e=int(f["eps_e"]), s1=float("nan"), s2=float("nan"))
    return ModelImage(arrays, scalars, fp, int(f["model_version"]), sha, L.version, qp.net())


def same_model(img: ModelImage, qp: QParams | QNet) -> bool:
    """Whether an image holds exactly these fixed-point parameters (every block's arrays and shifts)."""
    net = qp.net() if isinstance(qp, QParams) else qp
    got = img.qnet
    if got is None or got.hidden != net.hidden:
        return False
    same = all(np.array_equal(np.asarray(getattr(a, k)), np.asarray(getattr(b, k))) and (a.fg, a.fy, a.eps_m, a.eps_e)
               == (b.fg, b.fy, b.eps_m, b.eps_e) for a, b in zip(got.blocks, net.blocks) for k in QBlock.INT_ARRAYS)
    return same and all(np.array_equal(np.asarray(getattr(got, k)), np.asarray(getattr(net, k)))
                        for k in ("w_out", "b_out", "rsqrt_seed"))
