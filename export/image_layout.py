"""The model image's byte layout, described once: the Python writer and reader (model_image.py), the C
reader and the model store (through the generated firmware_c/include/slipest_image_layout.h, which
`c_header` writes: `python -m fleetlab.cli.image_layout_header`), the upload faults and every test that edits
an image are driven from here.

One class describes every format (`ImageLayout`): a packed little-endian header of named fields padded with
reserved zero bytes, a payload of little-endian arrays, a trailer (CRC-32, sha256) and, with flag HMAC, a tag.
Format 2 (any architecture) carries a layer table in its header: one fixed-size record per hidden block
(width and the block's shifts), so the payload's array sizes follow from the header. Format 1 (SN-S, the
format of the images already on rovers) is a profile of the same description: its widths are fixed to (30,),
its one block's record fields are header fields, and its GELU table follows the head. Every consumer looks
fields up by name, so a format adds rows, not copies.

Stdlib only, so that the build tools and the tests can read it without numpy.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import zlib
from dataclasses import dataclass
from fleetlab.errors import InputError


@dataclass(frozen=True)
class Field:
    """One header field: its name, struct code (little-endian, packed) and what it holds."""

    name: str
    code: str
    doc: str


@dataclass(frozen=True)
class Array:
    """One payload array: its name (the network's attribute), numpy little-endian dtype and element count: a
    number, or "in*width" / "width" in a block (the head: its inputs times the classes / the classes). `block`
    places an array of the head part in a block instead (format 1 keeps its block's GELU table after the head)."""

    name: str
    dtype: str
    count: int | str
    block: int | None = None

    @property
    def size(self) -> int:
        return int(self.dtype[2:]) * int(self.count)


def _offsets(fields: tuple[Field, ...]) -> dict[str, int]:
    out, off = {}, 0
    for f in fields:
        out[f.name] = off
        off += struct.calcsize("<" + f.code)
    return out


MAGIC = b"SLPM"
ARCH_SN_S = 1  # 12 features -> Linear(30) -> LayerNorm -> GELU -> Linear(3), fixed-point scheme 1
ARCH_TABLE = 2  # 12 features -> 1..MAX_LAYERS Linear -> LayerNorm -> GELU blocks -> Linear(3), scheme 1
FLAG_F32 = 0x0001  # the float32 model follows the fixed-point one
FLAG_HMAC = 0x0002  # an HMAC-SHA256 tag over header + payload follows the trailer
HMAC_SIZE = 32
MAX_LAYERS = 4  # records in the header's layer table (the scheme's cap; a build may accept fewer)
MAX_WIDTH = 256  # units of one block (the scheme's cap)
N_IN, N_OUT, GELU_N, RSQRT_SEED_N = 12, 3, 129, 24  # fixed by the flight interface and scheme 1


@dataclass(frozen=True)
class ImageLayout:
    """One image format. The header: fields packed from byte 0, reserved zeros up to header_size, and at
    `table_at` a table of `max_layers` records of `record_size` bytes (unused records zero). The payload: per
    block the arrays of `block_q`, then `head_q` and `tail_q`; with flag F32 the float eps, per block
    `block_f32`, then `head_f32`. Then the trailer and, with flag HMAC, the tag.

    A profile without a table (`table_at` None) has one block whose record fields are header fields, under the
    names `in_header` gives where they differ, and fixed `widths`."""

    version: int
    arch: int
    header_size: int
    header: tuple[Field, ...]
    record: tuple[Field, ...]
    block_q: tuple[Array, ...]
    head_q: tuple[Array, ...]
    tail_q: tuple[Array, ...]
    f32_scalar: str
    block_f32: tuple[Array, ...]
    head_f32: tuple[Array, ...]
    trailer: tuple[Field, ...]
    table_at: int | None = None
    record_size: int = 0
    max_layers: int = 1
    widths: tuple[int, ...] | None = None  # a profile's fixed widths (None: any, within the caps)
    in_header: tuple[tuple[str, str], ...] = ()  # (record field, header field) where the names differ (no table)

    @property
    def header_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.header))

    @property
    def trailer_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.trailer))

    @property
    def record_struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(f.code for f in self.record))

    @property
    def offsets(self) -> dict[str, int]:
        """Byte offset of every header field."""
        return _offsets(self.header)

    @property
    def record_offsets(self) -> dict[str, int]:
        return _offsets(self.record)

    @property
    def reserved_start(self) -> int:
        return self.header_struct.size

    @property
    def trailer_size(self) -> int:
        return self.trailer_struct.size

    def header_name(self, record_field: str) -> str:
        """The header field that holds a record field in a profile without a table."""
        return dict(self.in_header).get(record_field, record_field)

    def pack_header(self, fields: dict[str, object], records: list[dict[str, object]]) -> bytes:
        """The header: `fields` by name and one record per block (in the table, or for a profile without one in
        the header fields), every other byte zero."""
        if self.table_at is None:
            fields = {**fields, **{self.header_name(f.name): records[0][f.name] for f in self.record}}
        out = bytearray(self.header_struct.pack(*(fields[f.name] for f in self.header)).ljust(self.header_size, b"\0"))
        if self.table_at is not None:
            for i, rec in enumerate(records):
                self.record_struct.pack_into(out, self.table_at + i * self.record_size, *(rec[f.name] for f in self.record))
        return bytes(out)

    @staticmethod
    def _sized(arrays: tuple[Array, ...], n_in: int, width: int) -> list[Array]:
        counts = {"in*width": n_in * width, "width": width}
        return [Array(a.name, a.dtype, counts.get(a.count, a.count), a.block) for a in arrays]  # type: ignore[arg-type]

    def _payload(self, block: tuple[Array, ...], head: tuple[Array, ...],
                 widths: tuple[int, ...] | None) -> list[tuple[int | None, Array]]:
        out: list[tuple[int | None, Array]] = []
        n_in = N_IN
        for i, w in enumerate(widths or self.widths):
            out += [(i, a) for a in self._sized(block, n_in, w)]
            n_in = w
        return out + [(a.block, a) for a in self._sized(head, n_in, N_OUT)]

    def q_arrays_for(self, widths: tuple[int, ...] | None = None) -> list[tuple[int | None, Array]]:
        """(block index, or None for the network's own arrays, array) in payload order for these widths (a
        profile's own by default)."""
        return self._payload(self.block_q, self.head_q + self.tail_q, widths)

    def f32_arrays_for(self, widths: tuple[int, ...] | None = None) -> list[tuple[int | None, Array]]:
        """The same for the float section (after its eps)."""
        return self._payload(self.block_f32, self.head_f32, widths)

    def q_payload_size(self, widths: tuple[int, ...] | None = None) -> int:
        return sum(a.size for _, a in self.q_arrays_for(widths))

    def f32_payload_size(self, widths: tuple[int, ...] | None = None) -> int:
        return 4 + sum(a.size for _, a in self.f32_arrays_for(widths))

    def image_size(self, widths: tuple[int, ...] | None = None, f32: bool = True, tag: bool = True) -> int:
        """Bytes of an image of these widths (with the float model and an HMAC tag by default)."""
        return (self.header_size + self.q_payload_size(widths) + (self.f32_payload_size(widths) if f32 else 0)
                + self.trailer_size + (HMAC_SIZE if tag else 0))

    @property
    def max_size(self) -> int:
        """Largest image of a profile of fixed widths (float model and tag included)."""
        return self.image_size()

    @staticmethod
    def bytes_per(arrays: tuple[Array, ...], count: str) -> int:
        """Bytes that each weight ("in*width") or each unit ("width") adds to these block arrays."""
        return sum(int(a.dtype[2:]) for a in arrays if a.count == count)


# Header fields that several formats hold, with the same code and meaning; a format's own are written out where
# it lists its fields. The frame (magic to flags) is at the same offsets in every format: a reader finds the
# format before knowing it.
SHARED = {f.name: f for f in (
    Field("magic", "4s", '"SLPM"'),
    Field("format", "H", "format version"),
    Field("header_size", "H", "bytes of the header"),
    Field("flags", "H", "FLAG_* bits"),
    Field("n_in", "B", "input features"),
    Field("n_out", "B", "classes"),
    Field("rsqrt_seed_n", "B", "1/sqrt seed entries"),
    Field("gelu_step_log2", "B", "log2 of the GELU table step"),
    Field("eps_cap", "i", "LayerNorm variance cap (int32)"),
    Field("model_version", "I", "model version (anti-rollback)"),
    Field("hash32", "I", "first 4 bytes (big-endian) of the content sha256"),
    Field("payload_size", "I", "bytes between header and trailer"),
)}


def _fields(*fields: str | Field) -> tuple[Field, ...]:
    """Header fields in order: a name stands for the shared field of that name."""
    return tuple(SHARED[f] if isinstance(f, str) else f for f in fields)


TRAILER = (Field("crc32", "I", "CRC-32 (IEEE 802.3, zlib.crc32) of header + payload"),
           Field("sha256", "32s", "the bundle's sha256 content hash"))
# a block's fixed-point arrays, its float arrays and the head's, in payload order
BLOCK_Q = (Array("w", "<i2", "in*width"), Array("b", "<i4", "width"), Array("g", "<i2", "width"),
           Array("bb", "<i4", "width"))
BLOCK_F32 = (Array("w", "<f4", "in*width"), Array("b", "<f4", "width"), Array("gamma", "<f4", "width"),
             Array("beta", "<f4", "width"))
HEAD_Q = (Array("w_out", "<i2", "in*width"), Array("b_out", "<i4", "width"))
HEAD_F32 = (Array("w_out", "<f4", "in*width"), Array("b_out", "<f4", "width"))
RECORD = (
    Field("width", "H", "units of the block"),
    Field("h_bits", "B", "bits kept of the accumulators"),
    Field("e_bits", "B", "bits kept of the centred values"),
    Field("fz", "B", "fraction bits of z"),
    Field("fg", "B", "fraction bits of gamma"),
    Field("fy", "B", "fraction bits of the block output"),
    Field("eps_e", "b", "LayerNorm eps exponent (int8)"),
    Field("eps_m", "h", "LayerNorm eps mantissa (int16)"),
    Field("c", "i", "normalisation constant (int32)"),
)

# --- format 1: SN-S, its one block's fields in the header ---------------------------------------------------

V1 = ImageLayout(
    version=1,
    arch=ARCH_SN_S,
    header_size=64,
    header=_fields(
        "magic", "format", Field("arch", "H", "architecture id"), "header_size", "flags", "n_in",
        Field("n_hidden", "B", "hidden width"), "n_out", Field("gelu_n", "B", "GELU table entries"), "rsqrt_seed_n",
        Field("h_bits", "B", "hidden activation bits"),
        Field("e_bits", "B", "LayerNorm output bits"),
        Field("fz", "B", "layer-1 output shift"),
        Field("fg", "B", "GELU output shift"),
        Field("fy", "B", "head output shift"),
        "gelu_step_log2",
        Field("eps_e", "b", "LayerNorm eps exponent (int8)"),
        Field("eps_m", "h", "LayerNorm eps mantissa (int16)"),
        Field("c30", "i", "LayerNorm 1/n scale (int32)"),
        "eps_cap", "model_version", "hash32", "payload_size",
    ),
    record=RECORD,
    in_header=(("width", "n_hidden"), ("c", "c30")),
    widths=(30,),
    block_q=BLOCK_Q,
    head_q=HEAD_Q,
    tail_q=(Array("gelu", "<i2", GELU_N, block=0), Array("rsqrt_seed", "<u4", RSQRT_SEED_N)),
    f32_scalar="eps",
    block_f32=BLOCK_F32,
    head_f32=HEAD_F32,
    trailer=TRAILER,
)

# --- format 2: any architecture, the layer table ------------------------------------------------------------

V2 = ImageLayout(
    version=2,
    arch=ARCH_TABLE,
    header_size=112,
    header=_fields(
        "magic", "format", Field("arch", "H", "architecture id (ARCH_TABLE)"), "header_size", "flags", "n_in", "n_out",
        Field("n_layers", "B", "hidden blocks (records used in the layer table)"),
        Field("gelu_n", "B", "GELU table entries (per block)"), "rsqrt_seed_n", "gelu_step_log2",
        "eps_cap", "model_version", "hash32", "payload_size",
    ),
    record=RECORD,
    table_at=48,
    record_size=16,
    max_layers=MAX_LAYERS,
    block_q=BLOCK_Q + (Array("gelu", "<i2", GELU_N),),
    head_q=HEAD_Q,
    tail_q=(Array("rsqrt_seed", "<u4", RSQRT_SEED_N),),
    f32_scalar="eps",
    block_f32=BLOCK_F32,
    head_f32=HEAD_F32,
    trailer=TRAILER,
)
assert V2.record_struct.size <= V2.record_size and V2.header_struct.size <= V2.table_at
assert V2.table_at + V2.max_layers * V2.record_size <= V2.header_size
assert all(V1.offsets[k] == V2.offsets[k] for k in ("magic", "format", "arch", "header_size", "flags"))
assert all(V1.header_name(f.name) in V1.offsets for f in V1.record)

LAYOUTS: dict[int, ImageLayout] = {1: V1, 2: V2}
CURRENT = V1  # the layout the C reader and the store are generated from (format 2: the C reader is to come)


def layout_for(widths: tuple[int, ...]) -> ImageLayout:
    """The format a network of these widths is written in: format 1 for an SN-S (what every C reader of a rover
    reads), format 2 for any other."""
    return V1 if widths == V1.widths else V2


def layout_of(img: bytes) -> ImageLayout:
    """The layout named by an image's format field (at the same offset in every format)."""
    if len(img) < V1.offsets["format"] + 2:
        raise InputError(f"image of {len(img)} bytes has no format field")
    (version,) = struct.unpack_from("<H", img, V1.offsets["format"])
    if version not in LAYOUTS:
        raise InputError(f"model image format version {version}; this reader knows {', '.join(map(str, LAYOUTS))}")
    return LAYOUTS[version]


def layer_records(img: bytes, layout: ImageLayout = V2) -> list[dict[str, object]]:
    """The used records of an image's layer table, by name (a profile without a table: its one block's, from
    the header)."""
    fields = header_fields(img, layout)
    if layout.table_at is None:
        return [{f.name: fields[layout.header_name(f.name)] for f in layout.record}]
    n = int(fields["n_layers"])
    if not 1 <= n <= layout.max_layers:
        raise InputError(f"layer table of {n} blocks (1 to {layout.max_layers})")
    names = [f.name for f in layout.record]
    return [dict(zip(names, layout.record_struct.unpack_from(img, layout.table_at + i * layout.record_size)))
            for i in range(n)]


def _frame(img: bytes, layout: ImageLayout | None) -> ImageLayout:
    """The given layout, else the one the image's format field names (format 1 when it names none we
    know: the frame fields, magic to flags, are at the same offsets in every format)."""
    if layout is not None:
        return layout
    try:
        return layout_of(img)
    except ValueError:
        return V1


def header_fields(img: bytes, layout: ImageLayout | None = None) -> dict[str, object]:
    """The header fields of an image by name (no check beyond its length); the layout is the image's own
    unless one is given."""
    layout = _frame(img, layout)
    if len(img) < layout.header_size:
        raise InputError(f"image of {len(img)} bytes is shorter than its {layout.header_size}-byte header")
    return dict(zip((f.name for f in layout.header), layout.header_struct.unpack_from(img, 0)))


def body_size(img: bytes, layout: ImageLayout | None = None) -> int:
    """Bytes covered by the CRC (header + payload), from the image's length and its HMAC flag."""
    layout = _frame(img, layout)
    tag = HMAC_SIZE if int(header_fields(img, layout)["flags"]) & FLAG_HMAC else 0
    return len(img) - layout.trailer_size - tag


def reseal(img: bytes, key: bytes | None = None, layout: ImageLayout | None = None) -> bytes:
    """The image with its CRC-32 recomputed over its (edited) header + payload, so that a reader's other
    checks are reached; a signed image keeps its old tag unless `key` re-signs it."""
    layout = _frame(img, layout)
    body = body_size(img, layout)
    out = bytearray(img)
    struct.pack_into("<I", out, body, zlib.crc32(bytes(img[:body])))  # the CRC opens the trailer
    if key is not None:
        if len(img) != body + layout.trailer_size + HMAC_SIZE:
            raise InputError("reseal: a key was given for an image that carries no HMAC tag")
        out[body + layout.trailer_size:] = hmac.new(key, bytes(img[:body]), hashlib.sha256).digest()
    return bytes(out)


def patch_header(img: bytes, layout: ImageLayout | None = None, seal: bool = True, **fields: object) -> bytes:
    """The image with the named header fields set (`patch_header(img, arch=2)`) and, unless seal is
    False, its CRC resealed."""
    layout = _frame(img, layout)
    out = bytearray(img)
    offsets = layout.offsets
    codes = {f.name: f.code for f in layout.header}
    for name, value in fields.items():
        if name not in codes:
            raise InputError(f"patch_header: no header field {name!r} (fields: {', '.join(codes)})")
        struct.pack_into("<" + codes[name], out, offsets[name], value)
    return reseal(bytes(out), layout=layout) if seal else bytes(out)


# --- the C header --------------------------------------------------------------------------------------------

# format 1's arrays as C names them: the members of the flat SN-S model struct (sns_profile.py)
_C_NAMES = {"w": "w1", "b": "b1", "g": "gamma", "bb": "beta", "w_out": "w2", "b_out": "b2"}


def c_header(layout: ImageLayout = CURRENT) -> str:
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
        " * Generated by export/image_layout.py (python -m fleetlab.cli.image_layout_header [FILE]): do not edit.",
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
    for prefix, arrays in (("Q", layout.q_arrays_for()), ("F32", layout.f32_arrays_for())):
        if prefix == "F32":
            lines.append(f"#define SLIPEST_IMAGE_F32_AT {at}u /**< the float section (eps first), with flag F32 */")
            at += 4
        for _, a in arrays:
            name = _C_NAMES.get(a.name, a.name).upper()
            width = int(a.dtype[2:])
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_N {a.count}u /**< {name.lower()}: elements */")
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_BYTES {width}u /**< {name.lower()}: bytes each */")
            lines.append(f"#define SLIPEST_IMAGE_{prefix}_{name}_AT {at}u /**< {name.lower()}: offset of element 0 */")
            at += a.size
    lines += [
        "/** Bytes of the fixed-point payload. */",
        f"#define SLIPEST_IMAGE_Q_PAYLOAD {layout.q_payload_size()}u",
        "/** Bytes of the float32 payload (flag F32): eps and the arrays. */",
        f"#define SLIPEST_IMAGE_F32_PAYLOAD {layout.f32_payload_size()}u",
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


def _c_table_lines(t: ImageLayout) -> list[str]:
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
