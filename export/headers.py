"""C99 headers of a bundle (float and fixed-point parameters) and a parser that reads them back.

Each header defines `static const` arrays and one const model struct (slipest_model.h) named after
the bundle (`slipest_<c_name>_q` / `_f32`), so one C image can include several bundles' headers. Integers are written exactly;
floats with 9 significant digits (enough to round-trip any float32) and an `f` suffix, so the
values never depend on the compiler's or the generating host's float printing.

One writer serves every network. The model struct comes in two layouts (slipest_model.h): an SN-S's flat
struct (arrays w1, b1, ... sized by the public SN-S constants, the small-flash kernel's input) and the layer
table of any other network (per-block arrays and one row of shifts per block). Each layout is a list of
parts (`_Parts`) that `_header` assembles in the same frame.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import sns_profile
from .quant import EPS_CAP, GELU_N, GELU_STEP_LOG2, FloatBlock, FloatNet, QBlock, QNet
from fleetlab.errors import InputError

Q_HEADER = "slipest_model_q.h"
F32_HEADER = "slipest_model_f32.h"
DEFAULT_C_NAME = "main"
_C_NAME = re.compile(r"^[a-z][a-z0-9_]{0,23}$")

# --- the SN-S struct: arrays by their flat names (sns_profile.py), sized by the public header's constants ---
# (flat name, C type, numpy dtype, size expression)
Q_ARRAYS = (
    ("w1", "int16_t", np.int16, "SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES"),
    ("b1", "int32_t", np.int32, "SLIPEST_N_HIDDEN"),
    ("g", "int16_t", np.int16, "SLIPEST_N_HIDDEN"),
    ("bb", "int32_t", np.int32, "SLIPEST_N_HIDDEN"),
    ("w2", "int16_t", np.int16, "SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN"),
    ("b2", "int32_t", np.int32, "SLIPEST_N_CLASSES"),
    ("gelu", "int16_t", np.int16, "SLIPEST_Q_GELU_N"),
    ("rsqrt_seed", "uint32_t", np.uint32, "SLIPEST_Q_RSQRT_SEED_N"),
)
# flat name -> slipest_model_q_t member
Q_MEMBERS = {"w1": "w1", "b1": "b1", "g": "gamma", "bb": "beta", "w2": "w2", "b2": "b2", "gelu": "gelu",
             "rsqrt_seed": "rsqrt_seed"}
F32_ARRAYS = (
    ("w1", "SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES"),
    ("b1", "SLIPEST_N_HIDDEN"),
    ("gamma", "SLIPEST_N_HIDDEN"),
    ("beta", "SLIPEST_N_HIDDEN"),
    ("w2", "SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN"),
    ("b2", "SLIPEST_N_CLASSES"),
)
# Integer scheme scalars (manifest keys) that are members of slipest_model_q_t under the same name.
Q_SCALARS = ("n_in", "n_hidden", "n_out", "h_bits", "e_bits", "fz", "fg", "fy", "eps_m", "eps_e", "eps_cap",
             "gelu_step_log2", "gelu_n", "c30")
# sizes named by the public header slipest_model.h (the fixed SN-S architecture)
ARCH_SIZES = {"SLIPEST_N_FEATURES": 12, "SLIPEST_N_HIDDEN": 30, "SLIPEST_N_CLASSES": 3,
              "SLIPEST_Q_GELU_N": 129, "SLIPEST_Q_RSQRT_SEED_N": 24}

# --- the layer table (any other network) ---
# per-block arrays (QBlock attribute, slipest_layer_q_t member, C type, numpy dtype)
LAYER_Q_ARRAYS = (("w", "w", "int16_t", np.int16), ("b", "b", "int32_t", np.int32), ("g", "gamma", "int16_t", np.int16),
                  ("bb", "beta", "int32_t", np.int32), ("gelu", "gelu", "int16_t", np.int16))
# per-block scalars (QBlock attribute = slipest_layer_q_t member)
LAYER_Q_SCALARS = ("c", "width", "eps_m", "eps_e", "h_bits", "e_bits", "fz", "fg", "fy")
LAYER_F32_ARRAYS = ("w", "b", "gamma", "beta")


def check_c_name(name: str) -> str:
    """The bundle's C name: its models are slipest_<name>_q and slipest_<name>_f32."""
    if not _C_NAME.match(name):
        raise InputError(f"C model name {name!r}: use 1-24 lower-case letters, digits or _, starting with a letter")
    return name


def c_float(v: float) -> str:
    """A float32 as a C literal that round-trips exactly: 9 significant digits + 'f'."""
    v = np.float32(v)
    if not np.isfinite(v):
        raise InputError(f"cannot write a non-finite value ({v}) into a C header")
    s = format(float(v), ".9g")
    if not any(ch in s for ch in ".e"):
        s += ".0"
    return s + "f"


def c_int(v: int) -> str:
    v = int(v)
    return f"({v})" if v < 0 else str(v)


def _array(ctype: str, name: str, size: str, items: list[str], per_line: int) -> str:
    lines = [", ".join(items[i : i + per_line]) for i in range(0, len(items), per_line)]
    body = ",\n    ".join(lines)
    return f"static const {ctype} {name}[{size}] = {{\n    {body}\n}};\n"


def _ints(ctype: str, name: str, values, size: str | None = None) -> str:
    """An integer array, 12 a line; its size is the expression given or its length."""
    flat = np.asarray(values).reshape(-1).astype(np.int64)
    return _array(ctype, name, size or str(len(flat)), [str(int(v)) for v in flat], 12)


def _floats(name: str, values, size: str | None = None) -> str:
    """A float32 array, 6 a line; its size is the expression given or its length."""
    flat = np.asarray(values, dtype=np.float32).reshape(-1)
    return _array("float", name, size or str(len(flat)), [c_float(v) for v in flat], 6)


def _struct_members(items: list[tuple[str, str]], indent: str = "    ") -> str:
    return ",\n".join(f"{indent}.{k} = {v}" for k, v in items)


def _layer_table(ctype: str, name: str, layers: list[list[tuple[str, str]]], widest: int) -> str:
    rows = ",\n".join("    {\n" + _struct_members(items, "        ") + "\n    }" for items in layers)
    return (f"typedef char {name}_width_check[({widest} <= SLIPEST_MAX_WIDTH) ? 1 : -1];\n\n"
            f"static const {ctype} {name}[{len(layers)}] = {{\n{rows}\n}};\n\n")


@dataclass
class _Parts:
    """What one header holds between its frame (guard, comment, includes) and its closing #endif."""

    title: str  # the opening comment's first line
    note: str  # text before the arrays ("" or a comment)
    arrays: list[str]  # the C arrays, in order
    table: str  # the layer table ("" for the flat SN-S struct)
    members: list[tuple[str, str]]  # the model struct's members before .version and .hash32
    shape: str  # a C condition on the build's caps: the struct's compile-time check


def _sns_shape(m: dict[str, str]) -> str:
    return f"{m['n_in']} == SLIPEST_N_FEATURES && {m['n_hidden']} == SLIPEST_N_HIDDEN && {m['n_out']} == SLIPEST_N_CLASSES"


def _table_shape(m: dict[str, str]) -> str:
    return f"{m['n_in']} == SLIPEST_N_FEATURES && {m['n_out']} == SLIPEST_N_CLASSES && {m['n_layers']} <= SLIPEST_MAX_LAYERS"


def _sns_q(net: QNet, model: str) -> _Parts:
    sc, flat = sns_profile.scalars(net), sns_profile.q_arrays(net)
    note = (f"/* logits_real = logits_q / {sc['logit_scale']!r} (s2 * 2^FY); features in raw LSB units:\n"
            f" * {', '.join(format(v, 'g') for v in sc['feature_lsb'])} */\n\n")
    arrays = [_ints(ctype, f"{model}_{attr}", flat[attr], size) for attr, ctype, _, size in Q_ARRAYS]
    members = [(Q_MEMBERS[attr], f"{model}_{attr}") for attr, *_ in Q_ARRAYS]
    members += [(key, c_int(sc[key])) for key in Q_SCALARS] + [("rsqrt_seed_n", str(len(net.rsqrt_seed)))]
    return _Parts("SN-S fixed-point parameters (integer only).", note, arrays, "", members, _sns_shape(dict(members)))


def _sns_f32(fn: FloatNet, model: str) -> _Parts:
    flat = sns_profile.f32_arrays(fn)
    arrays = [_floats(f"{model}_{attr}", flat[attr], size) for attr, size in F32_ARRAYS]
    (n_hidden, n_in), n_out = flat["w1"].shape, flat["w2"].shape[0]
    members = [(attr, f"{model}_{attr}") for attr, _ in F32_ARRAYS]
    members += [("ln_eps", c_float(fn.eps)), ("n_in", str(n_in)), ("n_hidden", str(n_hidden)), ("n_out", str(n_out))]
    return _Parts("SN-S float32 parameters (for the float C path).", "", arrays, "", members, _sns_shape(dict(members)))


def _table_q(net: QNet, model: str) -> _Parts:
    arrays, layers = [], []
    for k, blk in enumerate(net.blocks):
        arrays += [_ints(ctype, f"{model}_l{k}_{attr}", getattr(blk, attr)) for attr, _, ctype, _ in LAYER_Q_ARRAYS]
        layers.append([(member, f"{model}_l{k}_{attr}") for attr, member, *_ in LAYER_Q_ARRAYS]
                      + [(key, c_int(getattr(blk, key))) for key in LAYER_Q_SCALARS])
    arrays += [_ints("int16_t", f"{model}_w2", net.w_out), _ints("int32_t", f"{model}_b2", net.b_out),
               _ints("uint32_t", f"{model}_rsqrt_seed", net.rsqrt_seed)]
    members = [("w2", f"{model}_w2"), ("b2", f"{model}_b2"), ("rsqrt_seed", f"{model}_rsqrt_seed"),
               ("layers", f"{model}_layers"), ("n_layers", str(len(net.blocks))), ("n_in", "12"), ("n_out", "3"),
               ("eps_cap", str(EPS_CAP)), ("gelu_step_log2", str(GELU_STEP_LOG2)), ("gelu_n", str(GELU_N)),
               ("rsqrt_seed_n", str(len(net.rsqrt_seed)))]
    arch = "-".join(str(h) for h in net.hidden)
    note = f"/* logits_real = logits_q / {net.logit_scale!r} (s_out * 2^FY of the last block) */\n\n"
    return _Parts(f"Fixed-point parameters (integer only), hidden blocks {arch}.", note, arrays,
                  _layer_table("slipest_layer_q_t", f"{model}_layers", layers, max(net.hidden)), members,
                  _table_shape(dict(members)))


def _table_f32(fn: FloatNet, model: str) -> _Parts:
    arrays, layers = [], []
    for k, blk in enumerate(fn.blocks):
        arrays += [_floats(f"{model}_l{k}_{attr}", getattr(blk, attr)) for attr in LAYER_F32_ARRAYS]
        layers.append([(attr, f"{model}_l{k}_{attr}") for attr in LAYER_F32_ARRAYS] + [("width", str(blk.w.shape[0]))])
    arrays += [_floats(f"{model}_{attr}", getattr(fn, attr)) for attr in ("w_out", "b_out")]
    members = [("w2", f"{model}_w_out"), ("b2", f"{model}_b_out"), ("layers", f"{model}_layers"),
               ("n_layers", str(len(fn.blocks))), ("ln_eps", c_float(fn.eps)), ("n_in", "12"), ("n_out", "3")]
    arch = "-".join(str(h) for h in fn.hidden)
    return _Parts(f"Float32 parameters (for the float C path), hidden blocks {arch}.", "", arrays,
                  _layer_table("slipest_layer_f32_t", f"{model}_layers", layers, max(fn.hidden)), members,
                  _table_shape(dict(members)))


def _header(kind: str, parts: _Parts, model: str, c_name: str, content_hash: str, version: int) -> str:
    """The header text: the frame around `parts`; kind "Q" or "F32" names the guard and the model struct's type."""
    guard = f"SLIPEST_MODEL_{kind}_{c_name.upper()}_H"
    latest = f"SLIPEST_MODEL_{kind}_INCLUDED"
    members = parts.members + [("version", f"{int(version)}u"), ("hash32", f"0x{content_hash[:8]}u")]
    return "".join([
        f"/* {parts.title}\n"
        " * Generated by `fleetlab export` (export/headers.py); do not edit: the bundle's\n"
        " * manifest.json records the sha256 of this file.\n"
        f" * Defines the const model {model} (slipest_model.h); content hash {content_hash}.\n"
        " * Scheme and roundings: docs/fixed_point.md. */\n"
        f"#ifndef {guard}\n#define {guard}\n\n#include <stdint.h>\n\n#include \"slipest_model.h\"\n\n",
        parts.note,
        *(a + "\n" for a in parts.arrays),
        parts.table,
        # C99 has no static_assert: a negative array size stops the build of a model beyond the build's caps
        f"typedef char {model}_shape_check[({parts.shape}) ? 1 : -1];\n\n",
        f"static const slipest_model_{kind.lower()}_t {model} = {{\n{_struct_members(members)}\n}};\n\n",
        "/* the model of the header included last, for sources that include exactly one bundle */\n",
        f"#undef {latest}\n#define {latest} {model}\n",
        f"\n#endif /* {guard} */\n",
    ])


def q_header_text(net: QNet, content_hash: str, c_name: str = DEFAULT_C_NAME, version: int = 1) -> str:
    """The fixed-point header: the flat struct for an SN-S, the layer table for any other network."""
    model = f"slipest_{check_c_name(c_name)}_q"
    parts = _sns_q(net, model) if sns_profile.fits(net) else _table_q(net, model)
    return _header("Q", parts, model, c_name, content_hash, version)


def f32_header_text(fn: FloatNet, content_hash: str, c_name: str = DEFAULT_C_NAME, version: int = 1) -> str:
    """The float32 header: the flat struct for an SN-S, the layer table for any other network."""
    model = f"slipest_{check_c_name(c_name)}_f32"
    parts = _sns_f32(fn, model) if sns_profile.fits(fn) else _table_f32(fn, model)
    return _header("F32", parts, model, c_name, content_hash, version)


def write_headers(out_dir: Path, net: QNet, fn: FloatNet, content_hash: str, c_name: str = DEFAULT_C_NAME,
                  version: int = 1) -> list[Path]:
    """Both headers of a model, the float one first."""
    out_dir = Path(out_dir)
    (out_dir / F32_HEADER).write_text(f32_header_text(fn, content_hash, c_name, version))
    (out_dir / Q_HEADER).write_text(q_header_text(net, content_hash, c_name, version))
    return [out_dir / F32_HEADER, out_dir / Q_HEADER]


# ---------------------------------------------------------------- parsing (for checks and tests)

_ARRAY = re.compile(r"static const (\w+) (\w+)\[([^\]]*)\] = \{([^}]*)\};", re.S)
_STRUCT = re.compile(r"static const (slipest_model_(?:q|f32)_t) (\w+) = \{(.*?)\n\};", re.S)
_MEMBER = re.compile(r"^\s*\.(\w+) = (\{[^}]*\}|[^,\n]+),?\s*$", re.M)


def parse_header(path: Path) -> tuple[dict[str, str], dict[str, tuple[str, str, list[str]]], str]:
    """(struct member -> text, array name -> (C type, size expression, value tokens), model name)."""
    path = Path(path)
    text = path.read_text()
    if "#endif" not in text.rsplit("}", 1)[-1]:
        raise InputError(f"{path}: header is truncated (no closing #endif)")
    m = _STRUCT.search(text)
    if m is None:
        raise InputError(f"{path}: no slipest_model_q_t / slipest_model_f32_t definition (old header format?)")
    members = {k: v.strip() for k, v in _MEMBER.findall(m[3])}
    arrays = {}
    for a in _ARRAY.finditer(text):
        tokens = [t.strip() for t in a[4].replace("\n", " ").split(",") if t.strip()]
        arrays[a[2]] = (a[1], a[3].strip(), tokens)
    return members, arrays, m[2]


def _size_of(expr: str) -> int:
    total = 1
    for part in expr.split("*"):
        part = part.strip()
        total *= ARCH_SIZES[part] if part in ARCH_SIZES else int(part)
    return total


def _int_member(members: dict[str, str], name: str, path: Path) -> int:
    if name not in members:
        raise InputError(f"{path}: model struct has no .{name}")
    return int(members[name].strip().strip("()").rstrip("uU"))


_HASH_COMMENT = re.compile(r"content hash ([0-9a-f]{64})\.")


def _header_hash(text: str, members: dict[str, str], path: Path) -> tuple[str, int]:
    """(full content hash from the header comment, hash32 member)."""
    m = _HASH_COMMENT.search(text)
    try:
        h32 = int(members["hash32"].rstrip("uU"), 16)
    except (KeyError, ValueError):
        raise InputError(f"{path}: missing or malformed .hash32 in the model struct") from None
    if m is None:
        raise InputError(f"{path}: no content hash in the header comment")
    return m[1], h32


def _array_of(arrays, name: str, ctype: str, path: Path) -> list[str]:
    if name not in arrays:
        raise InputError(f"{path}: missing array {name}")
    found_type, size_expr, tokens = arrays[name]
    n = _size_of(size_expr)
    if found_type != ctype or len(tokens) != n:
        raise InputError(f"{path}: array {name} is {found_type}[{len(tokens)}], expected {ctype}[{n}]")
    return tokens


def _ints_of(arrays, name: str, ctype: str, dtype, path: Path) -> np.ndarray:
    tokens = _array_of(arrays, name, ctype, path)
    return np.array([int(t.strip("()")) for t in tokens], dtype=np.int64).astype(dtype)


def _floats_of(arrays, name: str, path: Path) -> np.ndarray:
    return np.array([float(t.rstrip("fF")) for t in _array_of(arrays, name, "float", path)], np.float32)


def _eps_of(members: dict[str, str], path: Path) -> float:
    if "ln_eps" not in members:
        raise InputError(f"{path}: model struct has no .ln_eps")
    return float(np.float32(float(members["ln_eps"].rstrip("fF"))))


_LAYER_ROW = re.compile(r"\{\n((?:\s+\.\w+ = [^\n]+\n)+)\s+\}")


def _layer_rows(text: str, table: str, path: Path) -> list[dict[str, str]]:
    m = re.search(rf"static const \w+ {table}\[(\d+)\] = \{{\n(.*?)\n\}};", text, re.S)
    if m is None:
        raise InputError(f"{path}: no layer table {table}")
    rows = [{k: v.strip() for k, v in _MEMBER.findall(r)} for r in _LAYER_ROW.findall(m[2])]
    if len(rows) != int(m[1]):
        raise InputError(f"{path}: layer table {table} has {len(rows)} rows, declares {m[1]}")
    return rows


def _sns_q_of(members, arrays, model: str, path: Path) -> QNet:
    """The network of a flat SN-S struct; its integer members must be the scheme's for these parameters."""
    sc = {key: _int_member(members, key, path) for key in Q_SCALARS}
    flat = {attr: _ints_of(arrays, f"{model}_{attr}", ctype, dtype, path) for attr, ctype, dtype, _ in Q_ARRAYS}
    flat["w1"] = flat["w1"].reshape(sc["n_hidden"], sc["n_in"])
    flat["w2"] = flat["w2"].reshape(sc["n_out"], sc["n_hidden"])
    net = sns_profile.qnet(flat, sc["fg"], sc["fy"], sc["eps_m"], sc["eps_e"])
    scheme = sns_profile.scalars(net)
    for key, value in sc.items():
        if value != scheme[key]:
            raise InputError(f"{path}: .{key} = {value}, the scheme gives {scheme[key]}")
    return net


def _table_q_of(text: str, arrays, model: str, path: Path) -> QNet:
    """The network of a layer-table struct; each row's derived shifts must be those of its width."""
    blocks, n_in = [], 12
    for k, row in enumerate(_layer_rows(text, f"{model}_layers", path)):
        sc = {key: _int_member(row, key, path) for key in LAYER_Q_SCALARS}
        arr = {attr: _ints_of(arrays, f"{model}_l{k}_{attr}", ctype, dtype, path) for attr, _, ctype, dtype in LAYER_Q_ARRAYS}
        width = sc["width"]
        if arr["w"].size != width * n_in:
            raise InputError(f"{path}: block {k + 1} weights have {arr['w'].size} values, expected {width} x {n_in}")
        blk = QBlock(w=arr["w"].reshape(width, n_in), b=arr["b"], g=arr["g"], bb=arr["bb"], gelu=arr["gelu"],
                     fg=sc["fg"], fy=sc["fy"], eps_m=sc["eps_m"], eps_e=sc["eps_e"], s=float("nan"))
        derived = {key: getattr(blk, key) for key in ("c", "h_bits", "e_bits", "fz")}
        if any(derived[key] != sc[key] for key in derived):
            raise InputError(f"{path}: block {k + 1} shifts {sc} are not those of width {width} ({derived})")
        blocks.append(blk)
        n_in = width
    w2 = _ints_of(arrays, f"{model}_w2", "int16_t", np.int16, path)
    b2 = _ints_of(arrays, f"{model}_b2", "int32_t", np.int32, path)
    seed = _ints_of(arrays, f"{model}_rsqrt_seed", "uint32_t", np.int64, path)
    return QNet(blocks, w2.reshape(3, n_in), b2, float("nan"), seed)


def _table_f32_of(text: str, members, arrays, model: str, path: Path) -> FloatNet:
    blocks, n_in = [], 12
    for k, row in enumerate(_layer_rows(text, f"{model}_layers", path)):
        width = _int_member(row, "width", path)
        arr = {attr: _floats_of(arrays, f"{model}_l{k}_{attr}", path) for attr in LAYER_F32_ARRAYS}
        blocks.append(FloatBlock(w=arr["w"].reshape(width, n_in), b=arr["b"], gamma=arr["gamma"], beta=arr["beta"]))
        n_in = width
    w_out, b_out = _floats_of(arrays, f"{model}_w_out", path), _floats_of(arrays, f"{model}_b_out", path)
    return FloatNet(blocks, w_out.reshape(3, n_in), b_out, _eps_of(members, path))


def _sns_f32_of(members, arrays, model: str, path: Path) -> FloatNet:
    flat = {attr: _floats_of(arrays, f"{model}_{attr}", path) for attr, _ in F32_ARRAYS}
    nh, ni, no = (_int_member(members, k, path) for k in ("n_hidden", "n_in", "n_out"))
    flat["w1"], flat["w2"] = flat["w1"].reshape(nh, ni), flat["w2"].reshape(no, nh)
    return sns_profile.float_net(flat, _eps_of(members, path))


def read_q_header(path: Path) -> tuple[QNet, str, int]:
    """(the network, hash string, hash32) of a fixed-point header, either struct layout. The scales s are not
    in the header (NaN): the manifest records them."""
    path = Path(path)
    members, arrays, model = parse_header(path)
    text = path.read_text()
    net = (_table_q_of(text, arrays, model, path) if "layers" in members
           else _sns_q_of(members, arrays, model, path))
    return (net, *_header_hash(text, members, path))


def read_f32_header(path: Path) -> tuple[FloatNet, str, int]:
    """(the float network, hash string, hash32) of a float header, either struct layout."""
    path = Path(path)
    members, arrays, model = parse_header(path)
    text = path.read_text()
    fn = (_table_f32_of(text, members, arrays, model, path) if "layers" in members
          else _sns_f32_of(members, arrays, model, path))
    return (fn, *_header_hash(text, members, path))
