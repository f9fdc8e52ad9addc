"""The model image's byte layout, described once: the Python writer and reader (model_image.py), the C
reader and the model store (through the generated firmware_c/include/slipest_image_layout.h), the upload
faults and every test that edits an image are driven from here.

    python -m fleetlab.export.image_layout c FILE     -> the C layout header (committed; a test regenerates it)

Format 1 (the SN-S image) is a packed little-endian header of named fields padded with reserved zero bytes,
a payload of little-endian arrays in a fixed order, a trailer (CRC-32, sha256) and, with flag HMAC, a tag.
Format 2 (any architecture) has the same frame (magic, format, arch, header size and flags at the same
offsets, the same trailer and tag) and carries the layer table in its header: one fixed-size record per
hidden block (width and the block's shifts), so the payload's array sizes follow from the header. Every
consumer looks fields up by name, so a format adds rows, not copies.

Stdlib only, so that the build tools and the tests can read it without numpy.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Field:
    """One header field: its name, struct code (little-endian, packed) and what it holds."""

    name: str
    code: str
    doc: str


@dataclass(frozen=True)
class Array:
    """One payload array: its name, numpy little-endian dtype and element count."""

    name: str
    dtype: str
    count: int

    @property
    def size(self) -> int:
        return int(self.dtype[2:]) * self.count


def _offsets(fields: tuple[Field, ...]) -> dict[str, int]:
    out, off = {}, 0
    for f in fields:
        out[f.name] = off
        off += struct.calcsize("<" + f.code)
    return out


@dataclass(frozen=True)
class Layout:
    """One image format: header fields (packed from byte 0, then reserved zero bytes up to header_size),
    the fixed-point payload arrays, the optional float32 section (flag F32: a float scalar, then arrays)
    and the trailer fields."""

    version: int
    header_size: int
    header: tuple[Field, ...]
    q_arrays: tuple[Array, ...]
    f32_scalar: str
    f32_arrays: tuple[Array, ...]
    trailer: tuple[Field, ...]

    @property
    def header_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.header))

    @property
    def trailer_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.trailer))

    @property
    def offsets(self) -> dict[str, int]:
        """Byte offset of every header field."""
        return _offsets(self.header)

    @property
    def reserved_start(self) -> int:
        return self.header_struct.size

    @property
    def trailer_size(self) -> int:
        return self.trailer_struct.size

    @property
    def q_payload_size(self) -> int:
        return sum(a.size for a in self.q_arrays)

    @property
    def f32_payload_size(self) -> int:
        return 4 + sum(a.size for a in self.f32_arrays)

    @property
    def max_size(self) -> int:
        return self.header_size + self.q_payload_size + self.f32_payload_size + self.trailer_size + HMAC_SIZE


MAGIC = b"SLPM"
ARCH_SN_S = 1  # 12 features -> Linear(30) -> LayerNorm -> GELU -> Linear(3), fixed-point scheme 1
FLAG_F32 = 0x0001  # the float32 model follows the fixed-point one
FLAG_HMAC = 0x0002  # an HMAC-SHA256 tag over header + payload follows the trailer
HMAC_SIZE = 32

V1 = Layout(
    version=1,
    header_size=64,
    header=(
        Field("magic", "4s", '"SLPM"'),
        Field("format", "H", "format version"),
        Field("arch", "H", "architecture id"),
        Field("header_size", "H", "bytes of the header"),
        Field("flags", "H", "FLAG_* bits"),
        Field("n_in", "B", "input features"),
        Field("n_hidden", "B", "hidden width"),
        Field("n_out", "B", "classes"),
        Field("gelu_n", "B", "GELU table entries"),
        Field("rsqrt_seed_n", "B", "1/sqrt seed entries"),
        Field("h_bits", "B", "hidden activation bits"),
        Field("e_bits", "B", "LayerNorm output bits"),
        Field("fz", "B", "layer-1 output shift"),
        Field("fg", "B", "GELU output shift"),
        Field("fy", "B", "head output shift"),
        Field("gelu_step_log2", "B", "log2 of the GELU table step"),
        Field("eps_e", "b", "LayerNorm eps exponent (int8)"),
        Field("eps_m", "h", "LayerNorm eps mantissa (int16)"),
        Field("c30", "i", "LayerNorm 1/n scale (int32)"),
        Field("eps_cap", "i", "LayerNorm variance cap (int32)"),
        Field("model_version", "I", "model version (anti-rollback)"),
        Field("hash32", "I", "first 4 bytes (big-endian) of the content sha256"),
        Field("payload_size", "I", "bytes between header and trailer"),
    ),
    q_arrays=(Array("w1", "<i2", 360), Array("b1", "<i4", 30), Array("g", "<i2", 30), Array("bb", "<i4", 30),
              Array("w2", "<i2", 90), Array("b2", "<i4", 3), Array("gelu", "<i2", 129),
              Array("rsqrt_seed", "<u4", 24)),
    f32_scalar="eps",
    f32_arrays=(Array("w1", "<f4", 360), Array("b1", "<f4", 30), Array("gamma", "<f4", 30),
                Array("beta", "<f4", 30), Array("w2", "<f4", 90), Array("b2", "<f4", 3)),
    trailer=(Field("crc32", "I", "CRC-32 (IEEE 802.3, zlib.crc32) of header + payload"),
             Field("sha256", "32s", "the bundle's sha256 content hash")),
)

# --- format 2: the layer table ------------------------------------------------------------------------------

ARCH_TABLE = 2  # 12 features -> 1..MAX_LAYERS Linear -> LayerNorm -> GELU blocks -> Linear(3), scheme 1
MAX_LAYERS = 4  # records in the header's layer table (the scheme's cap; a build may accept fewer)
MAX_WIDTH = 256  # units of one block (the scheme's cap)
N_IN, N_OUT, GELU_N, RSQRT_SEED_N = 12, 3, 129, 24  # fixed by the flight interface and scheme 1


@dataclass(frozen=True)
class TableLayout:
    """Format 2: the frame of format 1 (header fields from byte 0, reserved zeros, trailer, tag) with a
    table of `max_layers` records of `record_size` bytes at `table_at` in the header (unused records
    zero). The payload: per block the arrays of `block_q` (counts "in*width", "width" or a number),
    then `head_q` and `tail_q`; with flag F32 the float eps, per block `block_f32`, then `head_f32`."""

    version: int
    header_size: int
    header: tuple[Field, ...]
    table_at: int
    record: tuple[Field, ...]
    record_size: int
    max_layers: int
    block_q: tuple[Array, ...]
    head_q: tuple[Array, ...]
    tail_q: tuple[Array, ...]
    f32_scalar: str
    block_f32: tuple[Array, ...]
    head_f32: tuple[Array, ...]
    trailer: tuple[Field, ...]

    header_struct = Layout.header_struct
    trailer_struct = Layout.trailer_struct
    offsets = Layout.offsets
    reserved_start = Layout.reserved_start
    trailer_size = Layout.trailer_size

    @property
    def record_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.record))

    @property
    def record_offsets(self) -> dict[str, int]:
        return _offsets(self.record)

    @staticmethod
    def _sized(arrays: tuple[Array, ...], n_in: int, width: int) -> list[Array]:
        counts = {"in*width": n_in * width, "width": width}
        return [Array(a.name, a.dtype, counts.get(a.count, a.count)) for a in arrays]  # type: ignore[arg-type]

    def _payload(self, block: tuple[Array, ...], head: tuple[Array, ...],
                 widths: tuple[int, ...]) -> list[tuple[int | None, Array]]:
        out: list[tuple[int | None, Array]] = []
        n_in = N_IN
        for i, w in enumerate(widths):
            out += [(i, a) for a in self._sized(block, n_in, w)]
            n_in = w
        return out + [(None, a) for a in self._sized(head, n_in, N_OUT)]

    def q_arrays_for(self, widths: tuple[int, ...]) -> list[tuple[int | None, Array]]:
        """(block index or None for the head and tail, array) in payload order for these widths."""
        return self._payload(self.block_q, self.head_q + self.tail_q, widths)

    def f32_arrays_for(self, widths: tuple[int, ...]) -> list[tuple[int | None, Array]]:
        """The same for the float section (after its eps)."""
        return self._payload(self.block_f32, self.head_f32, widths)

    def q_payload_size(self, widths: tuple[int, ...]) -> int:
        return sum(a.size for _, a in self.q_arrays_for(widths))

    def f32_payload_size(self, widths: tuple[int, ...]) -> int:
        return 4 + sum(a.size for _, a in self.f32_arrays_for(widths))

    def image_size(self, widths: tuple[int, ...], f32: bool = True, tag: bool = True) -> int:
        """Bytes of an image of these widths (with the float model and an HMAC tag by default)."""
        return (self.header_size + self.q_payload_size(widths) + (self.f32_payload_size(widths) if f32 else 0)
                + self.trailer_size + (HMAC_SIZE if tag else 0))

    @staticmethod
    def bytes_per(arrays: tuple[Array, ...], count: str) -> int:
        """Bytes that each weight ("in*width") or each unit ("width") adds to these block arrays."""
        return sum(int(a.dtype[2:]) for a in arrays if a.count == count)


V2 = TableLayout(
    version=2,
    header_size=112,
    header=(
        Field("magic", "4s", '"SLPM"'),
        Field("format", "H", "format version"),
        Field("arch", "H", "architecture id (ARCH_TABLE)"),
        Field("header_size", "H", "bytes of the header"),
        Field("flags", "H", "FLAG_* bits"),
        Field("n_in", "B", "input features"),
        Field("n_out", "B", "classes"),
        Field("n_layers", "B", "hidden blocks (records used in the layer table)"),
        Field("gelu_n", "B", "GELU table entries (per block)"),
        Field("rsqrt_seed_n", "B", "1/sqrt seed entries"),
        Field("gelu_step_log2", "B", "log2 of the GELU table step"),
        Field("eps_cap", "i", "LayerNorm variance cap (int32)"),
        Field("model_version", "I", "model version (anti-rollback)"),
        Field("hash32", "I", "first 4 bytes (big-endian) of the content sha256"),
        Field("payload_size", "I", "bytes between header and trailer"),
    ),
    table_at=48,
    record=(
        Field("width", "H", "units of the block"),
        Field("h_bits", "B", "bits kept of the accumulators"),
        Field("e_bits", "B", "bits kept of the centred values"),
        Field("fz", "B", "fraction bits of z"),
        Field("fg", "B", "fraction bits of gamma"),
        Field("fy", "B", "fraction bits of the block output"),
        Field("eps_e", "b", "LayerNorm eps exponent (int8)"),
        Field("eps_m", "h", "LayerNorm eps mantissa (int16)"),
        Field("c", "i", "normalisation constant (int32)"),
    ),
    record_size=16,
    max_layers=MAX_LAYERS,
    block_q=(Array("w", "<i2", "in*width"), Array("b", "<i4", "width"), Array("g", "<i2", "width"),  # type: ignore[arg-type]
             Array("bb", "<i4", "width"), Array("gelu", "<i2", GELU_N)),
    head_q=(Array("w_out", "<i2", "in*width"), Array("b_out", "<i4", "width")),  # type: ignore[arg-type]
    tail_q=(Array("rsqrt_seed", "<u4", RSQRT_SEED_N),),
    f32_scalar="eps",
    block_f32=(Array("w", "<f4", "in*width"), Array("b", "<f4", "width"), Array("gamma", "<f4", "width"),  # type: ignore[arg-type]
               Array("beta", "<f4", "width")),
    head_f32=(Array("w_out", "<f4", "in*width"), Array("b_out", "<f4", "width")),  # type: ignore[arg-type]
    trailer=V1.trailer,
)
assert V2.record_struct.size <= V2.record_size and V2.header_struct.size <= V2.table_at
assert V2.table_at + V2.max_layers * V2.record_size <= V2.header_size
assert all(V1.offsets[k] == V2.offsets[k] for k in ("magic", "format", "arch", "header_size", "flags"))

LAYOUTS: dict[int, Layout | TableLayout] = {1: V1, 2: V2}
CURRENT = V1  # the layout the C reader and the store are generated from (format 2: the C reader is to come)


def layout_of(img: bytes) -> Layout | TableLayout:
    """The layout named by an image's format field (at the same offset in every format)."""
    if len(img) < V1.offsets["format"] + 2:
        raise ValueError(f"image of {len(img)} bytes has no format field")
    (version,) = struct.unpack_from("<H", img, V1.offsets["format"])
    if version not in LAYOUTS:
        raise ValueError(f"model image format version {version}; this reader knows {', '.join(map(str, LAYOUTS))}")
    return LAYOUTS[version]


def layer_records(img: bytes, layout: TableLayout = V2) -> list[dict[str, object]]:
    """The used records of a format-2 image's layer table, by name."""
    n = int(header_fields(img, layout)["n_layers"])
    if not 1 <= n <= layout.max_layers:
        raise ValueError(f"layer table of {n} blocks (1 to {layout.max_layers})")
    names = [f.name for f in layout.record]
    return [dict(zip(names, layout.record_struct.unpack_from(img, layout.table_at + i * layout.record_size)))
            for i in range(n)]


AnyLayout = Layout | TableLayout


def _frame(img: bytes, layout: AnyLayout | None) -> AnyLayout:
    """The given layout, else the one the image's format field names (format 1 when it names none we
    know: the frame fields, magic to flags, are at the same offsets in every format)."""
    if layout is not None:
        return layout
    try:
        return layout_of(img)
    except ValueError:
        return V1


def header_fields(img: bytes, layout: AnyLayout | None = None) -> dict[str, object]:
    """The header fields of an image by name (no check beyond its length); the layout is the image's own
    unless one is given."""
    layout = _frame(img, layout)
    if len(img) < layout.header_size:
        raise ValueError(f"image of {len(img)} bytes is shorter than its {layout.header_size}-byte header")
    return dict(zip((f.name for f in layout.header), layout.header_struct.unpack_from(img, 0)))


def body_size(img: bytes, layout: AnyLayout | None = None) -> int:
    """Bytes covered by the CRC (header + payload), from the image's length and its HMAC flag."""
    layout = _frame(img, layout)
    tag = HMAC_SIZE if int(header_fields(img, layout)["flags"]) & FLAG_HMAC else 0
    return len(img) - layout.trailer_size - tag


def reseal(img: bytes, key: bytes | None = None, layout: AnyLayout | None = None) -> bytes:
    """The image with its CRC-32 recomputed over its (edited) header + payload, so that a reader's other
    checks are reached; a signed image keeps its old tag unless `key` re-signs it."""
    layout = _frame(img, layout)
    body = body_size(img, layout)
    out = bytearray(img)
    struct.pack_into("<I", out, body, zlib.crc32(bytes(img[:body])))  # the CRC opens the trailer
    if key is not None:
        if len(img) != body + layout.trailer_size + HMAC_SIZE:
            raise ValueError("reseal: a key was given for an image that carries no HMAC tag")
        out[body + layout.trailer_size:] = hmac.new(key, bytes(img[:body]), hashlib.sha256).digest()
    return bytes(out)


def patch_header(img: bytes, layout: AnyLayout | None = None, seal: bool = True, **fields: object) -> bytes:
    """The image with the named header fields set (`patch_header(img, arch=2)`) and, unless seal is
    False, its CRC resealed."""
    layout = _frame(img, layout)
    out = bytearray(img)
    offsets = layout.offsets
    codes = {f.name: f.code for f in layout.header}
    for name, value in fields.items():
        if name not in codes:
            raise ValueError(f"patch_header: no header field {name!r} (fields: {', '.join(codes)})")
        struct.pack_into("<" + codes[name], out, offsets[name], value)
    return reseal(bytes(out), layout=layout) if seal else bytes(out)


# --- the C header --------------------------------------------------------------------------------------------

_C_NAMES = {"g": "gamma", "bb": "beta"}  # Python (QParams) names that C spells as the model struct does


def c_header(layout: Layout = CURRENT) -> str:
    """firmware_c/include/slipest_image_layout.h: every offset and size of `layout` as C constants."""
    offsets = layout.offsets
    trailer_off, off = {}, 0
    for f in layout.trailer:
        trailer_off[f.name] = off
        off += struct.calcsize("<" + f.code)
    lines = [
        "/**",
        " * @file slipest_image_layout.h",
        " * @brief The model image's byte layout (docs/fixed_point.md, \"Model image\"): every offset is from",
        " *        the start of the image, every field little-endian.",
        " *",
        " * Generated by export/image_layout.py (python -m fleetlab.export.image_layout c FILE): do not edit.",
        " */",
        "#ifndef SLIPEST_IMAGE_LAYOUT_H",
        "#define SLIPEST_IMAGE_LAYOUT_H",
        "",
        "#ifdef __cplusplus",
        'extern "C" {',
        "#endif",
        "",
        f"/** Magic of a model image (\"{MAGIC.decode()}\"). */",
        f"#define SLIPEST_IMAGE_MAGIC \"{MAGIC.decode()}\"",
        "/** Image format version this reader understands. */",
        f"#define SLIPEST_IMAGE_FORMAT {layout.version}u",
        "/** Architecture id of SN-S (12 -> 30 -> LayerNorm -> GELU -> 3, fixed-point scheme 1). */",
        f"#define SLIPEST_IMAGE_ARCH_SN_S {ARCH_SN_S}u",
        "/** Bytes of the image header. */",
        f"#define SLIPEST_IMAGE_HEADER_SIZE {layout.header_size}u",
        "/** Bytes of the trailer: CRC-32 and the 32-byte sha256 content hash. */",
        f"#define SLIPEST_IMAGE_TRAILER_SIZE {layout.trailer_size}u",
        "/** Header flag: the image carries the float32 model after the fixed-point one. */",
        f"#define SLIPEST_IMAGE_FLAG_F32 0x{FLAG_F32:04X}u",
        "/** Header flag: an HMAC-SHA256 tag over header and payload follows the trailer. */",
        f"#define SLIPEST_IMAGE_FLAG_HMAC 0x{FLAG_HMAC:04X}u",
        "/** Bytes of the HMAC-SHA256 tag (present when SLIPEST_IMAGE_FLAG_HMAC is set). */",
        f"#define SLIPEST_IMAGE_HMAC_SIZE {HMAC_SIZE}u",
        "/** Largest valid image (with the float32 model and an HMAC tag), for sizing a receive buffer. */",
        f"#define SLIPEST_IMAGE_MAX_SIZE {layout.max_size}u",
        "",
        "/* header fields: byte offsets */",
    ]
    lines += [f"#define SLIPEST_IMAGE_OFF_{f.name.upper()} {offsets[f.name]}u /**< {f.code}: {f.doc} */"
              for f in layout.header]
    lines += [
        "/** First reserved (zero) header byte. */",
        f"#define SLIPEST_IMAGE_OFF_RESERVED {layout.reserved_start}u",
        "/* trailer fields: byte offsets from the end of the payload */",
    ]
    lines += [f"#define SLIPEST_IMAGE_TRAILER_OFF_{f.name.upper()} {trailer_off[f.name]}u /**< {f.doc} */"
              for f in layout.trailer]
    lines += ["", "/* payload: the fixed-point arrays in order (element bytes, count), then with flag F32 the",
              " * float32 LayerNorm eps and the float32 arrays */"]
    at = layout.header_size
    for prefix, arrays in (("Q", layout.q_arrays), ("F32", layout.f32_arrays)):
        if prefix == "F32":
            lines.append(f"#define SLIPEST_IMAGE_F32_AT {at}u /**< the float section (eps first), with flag F32 */")
            at += 4
        for a in arrays:
            name = _C_NAMES.get(a.name, a.name).upper()
            width = int(a.dtype[2:])
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_N {a.count}u /**< {name.lower()}: elements */")
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_BYTES {width}u /**< {name.lower()}: bytes each */")
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_AT {at}u /**< {name.lower()}: offset of element 0 */")
            at += a.size
    lines += [
        "/** Bytes of the fixed-point payload. */",
        f"#define SLIPEST_IMAGE_Q_PAYLOAD {layout.q_payload_size}u",
        "/** Bytes of the float32 payload (flag F32): eps and the arrays. */",
        f"#define SLIPEST_IMAGE_F32_PAYLOAD {layout.f32_payload_size}u",
        "",
    ] + _c_table_lines(V2) + [
        "",
        "#ifdef __cplusplus",
        "}",
        "#endif",
        "",
        "#endif /* SLIPEST_IMAGE_LAYOUT_H */",
        "",
    ]
    return "\n".join(lines)


def _c_table_lines(t: TableLayout) -> list[str]:
    """The format-2 part of the C header: the header fields that format 1 lacks or places elsewhere, the
    layer-table record and the payload's sizes per weight, per unit and per block (its size formula)."""
    per_w_q, per_u_q = t.bytes_per(t.block_q, "in*width"), t.bytes_per(t.block_q, "width")
    per_w_f, per_u_f = t.bytes_per(t.block_f32, "in*width"), t.bytes_per(t.block_f32, "width")
    gelu = sum(a.size for a in t.block_q if isinstance(a.count, int))
    tail = sum(a.size for a in t.tail_q)
    lines = [
        f"/* format {t.version}: any architecture, the layer table in the header (same frame as format 1:",
        " * magic, format, arch, header size and flags at the offsets above, the same trailer and tag) */",
        f"#define SLIPEST_IMAGE_V2_FORMAT {t.version}u /**< format version of a layer-table image */",
        "/** Architecture id of a layer-table model (1..4 Linear -> LayerNorm -> GELU blocks, scheme 1). */",
        f"#define SLIPEST_IMAGE_ARCH_TABLE {ARCH_TABLE}u",
        f"#define SLIPEST_IMAGE_V2_HEADER_SIZE {t.header_size}u /**< bytes of a format-2 header, layer table included */",
    ]
    lines += [f"#define SLIPEST_IMAGE_V2_OFF_{f.name.upper()} {t.offsets[f.name]}u /**< {f.code}: {f.doc} */"
              for f in t.header]
    lines += [
        "/** First reserved (zero) byte before the layer table. */",
        f"#define SLIPEST_IMAGE_V2_OFF_RESERVED {t.reserved_start}u",
        f"#define SLIPEST_IMAGE_V2_TABLE_AT {t.table_at}u /**< the layer table: one record per block */",
        f"#define SLIPEST_IMAGE_V2_RECORD_SIZE {t.record_size}u /**< bytes per record (zero padded) */",
        f"#define SLIPEST_IMAGE_V2_RECORDS {t.max_layers}u /**< records in the table (unused ones zero) */",
    ]
    lines += [f"#define SLIPEST_IMAGE_V2_REC_{f.name.upper()} {t.record_offsets[f.name]}u /**< {f.code}: {f.doc} */"
              for f in t.record]
    lines += [
        f"#define SLIPEST_IMAGE_V2_REC_END {t.record_struct.size}u /**< first padding byte of a record */",
        "/* payload: per block w [width * n_in], b, gamma, beta [width], gelu [129]; the head w [3 * width],",
        " * b [3]; the 1/sqrt seeds [24]; with flag F32: eps, per block w, b, gamma, beta, the head w, b */",
        f"#define SLIPEST_IMAGE_V2_Q_PER_WEIGHT {per_w_q}u /**< fixed-point bytes per weight */",
        f"#define SLIPEST_IMAGE_V2_Q_PER_UNIT {per_u_q}u /**< fixed-point bytes per unit (b, gamma, beta) */",
        f"#define SLIPEST_IMAGE_V2_Q_PER_BLOCK {gelu}u /**< fixed-point bytes per block (the GELU table) */",
        f"#define SLIPEST_IMAGE_V2_Q_TAIL {tail}u /**< the 1/sqrt seeds after the head */",
        f"#define SLIPEST_IMAGE_V2_F32_PER_WEIGHT {per_w_f}u /**< float bytes per weight */",
        f"#define SLIPEST_IMAGE_V2_F32_PER_UNIT {per_u_f}u /**< float bytes per unit (b, gamma, beta) */",
        "/** Bytes of a format-2 image with `weights` weights (every block and the head), `units` biases (every",
        " *  block's units and the 3 classes; gamma and beta of the head's 3 do not exist, hence - 3), `blocks`",
        " *  blocks, the float model and an HMAC tag: the largest image a build's caps admit. */",
        "#define SLIPEST_IMAGE_V2_SIZE(weights, units, blocks) \\",
        f"    ({t.header_size}u + ((weights) * {per_w_q + per_w_f}u) + (((units) - 3u) * {per_u_q + per_u_f}u) + "
        f"3u * {4 + 4}u + ((blocks) * {gelu}u) + {tail}u + 4u + \\",
        f"     {t.trailer_size}u + {HMAC_SIZE}u)",
    ]
    return lines


C_HEADER = Path(__file__).resolve().parents[1] / "firmware_c" / "include" / "slipest_image_layout.h"


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != "c":
        print("usage: python -m fleetlab.export.image_layout c FILE   (writes the C layout header)", file=sys.stderr)
        return 2
    Path(argv[1]).write_text(c_header(), encoding="utf-8", newline="\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
