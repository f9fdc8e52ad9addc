"""Test vectors of a bundle: inputs, their integer features, torch float and integer-reference logits.

Rows: real-looking windows (from dataset folders when given, else from a small run of the
simulator, else a built-in set of plausible windows and random draws around them), then edge cases: all zeros, each feature at
its int16 extremes, everything at the extremes, and values beyond int16 that saturate.

vectors.bin is the same content for C test programs: a 32-byte little-endian header
(magic "SLPV", version, N, n_in, n_out, n_arrays, header bytes, 0) then the arrays back to
back in VECTOR_ARRAYS order, each row-major little-endian. The manifest records the offsets.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from fleetlab.data.contracts import N_CLASSES, N_FEATURES
from fleetlab.data.features_int import FEATURE_LSB, quantize_features
from fleetlab.errors import InputError

BIN_MAGIC = b"SLPV"
BIN_VERSION = 1
BIN_HEADER = struct.Struct("<4s7I")  # magic, version, n, n_in, n_out, n_arrays, header_bytes, reserved

# name, little-endian dtype, columns (0 = one value per row)
VECTOR_ARRAYS: tuple[tuple[str, str, int], ...] = (
    ("inputs", "<f4", N_FEATURES),
    ("q_inputs", "<i2", N_FEATURES),
    ("torch_logits", "<f4", N_CLASSES),
    ("q_logits", "<i4", N_CLASSES),
    ("q_class", "<i4", 0),
    ("f_class", "<i4", 0),
    ("q_saturations", "<i4", 0),
)

# Plausible windows in physical units (feature order of contracts.FEATURE_NAMES): driving on flat
# ground, on a slope, digging in with high current, near standstill, and a rough traverse.
PROTOTYPES = np.array(
    [
        [3.0, 0.05, 35.0, 2.0, 0.02, 0.10, 0.01, 0.08, 1.62, 0.15, 0.02, 0.01],
        [2.5, 0.20, 50.0, 6.0, -0.20, 0.40, 0.05, 0.30, 1.55, 0.60, 0.25, -0.05],
        [4.5, 0.60, 75.0, 20.0, 0.10, 1.50, -0.10, 1.00, 1.40, 3.00, 0.40, 0.30],
        [0.1, 0.02, 5.0, 0.5, 0.00, 0.05, 0.00, 0.05, 1.62, 0.08, -0.01, 0.00],
        [5.5, 0.90, 60.0, 30.0, -0.15, 2.50, 0.15, 1.50, 0.30, 4.50, -0.60, 0.80],
    ],
    dtype=np.float64,
)
# Features that are standard deviations (kept >= 0 in random draws).
STD_COLUMNS = np.array([1, 3, 5, 7, 9])


@dataclass
class Vectors:
    inputs: np.ndarray
    q_inputs: np.ndarray
    torch_logits: np.ndarray
    q_logits: np.ndarray
    q_class: np.ndarray
    f_class: np.ndarray
    q_saturations: np.ndarray
    input_saturations: int = 0  # float -> int16 saturations while quantising the inputs

    def __len__(self) -> int:
        return len(self.inputs)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name, _, _ in VECTOR_ARRAYS}


def builtin_windows(n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` random windows around the built-in prototypes (multiplicative spread on scale features)."""
    base = PROTOTYPES[rng.integers(0, len(PROTOTYPES), n)]
    spread = np.abs(PROTOTYPES).mean(axis=0) * 0.35
    x = base + rng.normal(size=base.shape) * spread
    x[:, STD_COLUMNS] = np.abs(x[:, STD_COLUMNS])
    x[:, 0] = np.abs(x[:, 0])
    x[:, 2] = np.abs(x[:, 2])
    return np.vstack([PROTOTYPES, x])


def simulator_windows(seed: int, scale: float = 0.05) -> np.ndarray | None:
    """Windows of a small run of the built-in simulator scenario, or None if it is unavailable."""
    try:
        from fleetlab.data.csvio import WindowTable
        from fleetlab.data.simulator.scenario import scenario_traces
    except ImportError:
        return None
    traces = scenario_traces(seed, scale, progress=True)
    return np.concatenate([WindowTable.from_windows(t.windows()).features for _, _, t in traces])


def edge_windows() -> np.ndarray:
    """Zeros, each feature at its int16 extremes (others zero), all at the extremes, saturating values."""
    rows = [np.zeros(N_FEATURES)]
    for j in range(N_FEATURES):
        for raw in (32767, -32768, 40000, -40000):
            r = np.zeros(N_FEATURES)
            r[j] = raw * FEATURE_LSB[j]
            rows.append(r)
    for raw in (32767, -32768, 1, -1):
        rows.append(raw * FEATURE_LSB)
    alt = np.where(np.arange(N_FEATURES) % 2 == 0, 32767, -32768) * FEATURE_LSB
    rows += [alt, -alt - FEATURE_LSB]
    return np.array(rows)


def draw_inputs(n: int, data_windows: np.ndarray | None, seed: int) -> np.ndarray:
    """About `n` rows: real-looking windows (data if given, with random draws to fill up) + edge cases."""
    rng = np.random.default_rng(seed)
    edges = edge_windows()
    n_body = max(n - len(edges), 1)
    if data_windows is not None and len(data_windows):
        data_windows = np.asarray(data_windows, dtype=np.float64)
        take = min(len(data_windows), n_body)
        body = data_windows[rng.choice(len(data_windows), take, replace=False)]
        if take < n_body:  # fill up with jittered copies of data rows
            extra = body[rng.integers(0, take, n_body - take)]
            body = np.vstack([body, extra * (1 + 0.05 * rng.normal(size=extra.shape))])
    else:
        body = builtin_windows(n_body - len(PROTOTYPES), rng)
    return np.vstack([body, edges]).astype(np.float32)


def make_vectors(model: torch.nn.Module, qparams, inputs: np.ndarray) -> Vectors:
    """Float and integer-reference outputs for `inputs` (float32, physical units)."""
    from .intref import argmax_lowest, run

    inputs = np.asarray(inputs, dtype=np.float32)
    with torch.no_grad():
        torch_logits = model.eval()(torch.from_numpy(inputs)).numpy().astype(np.float32)
    q_inputs, n_sat = quantize_features(inputs, return_saturations=True)
    if qparams is not None:
        q_logits, q_sat = run(qparams, q_inputs)
    else:  # --onnx-only: no fixed-point path
        q_logits, q_sat = np.zeros((len(inputs), N_CLASSES), np.int32), np.zeros(len(inputs), np.int32)
    return Vectors(
        inputs=inputs, q_inputs=q_inputs.astype(np.int16), torch_logits=torch_logits, q_logits=q_logits,
        q_class=argmax_lowest(q_logits), f_class=argmax_lowest(torch_logits), q_saturations=q_sat,
        input_saturations=int(n_sat),
    )


def bin_layout(n: int) -> dict:
    """Offsets of every array in vectors.bin (recorded in the manifest)."""
    offset = BIN_HEADER.size
    arrays = []
    for name, dtype, cols in VECTOR_ARRAYS:
        shape = [n, cols] if cols else [n]
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        arrays.append({"name": name, "dtype": dtype, "shape": shape, "offset": offset, "bytes": nbytes})
        offset += nbytes
    return {
        "magic": BIN_MAGIC.decode(), "version": BIN_VERSION, "byte_order": "little",
        "header": "char magic[4]; uint32 version, n, n_in, n_out, n_arrays, header_bytes, reserved",
        "header_bytes": BIN_HEADER.size, "arrays": arrays, "total_bytes": offset,
    }


def write_vectors(bundle: Path, v: Vectors) -> tuple[Path, Path]:
    bundle = Path(bundle)
    npz = bundle / "vectors.npz"
    with open(npz, "wb") as f:  # a file object keeps numpy from appending ".npz" twice
        np.savez(f, **v.arrays())
    n = len(v)
    parts = [BIN_HEADER.pack(BIN_MAGIC, BIN_VERSION, n, N_FEATURES, N_CLASSES, len(VECTOR_ARRAYS), BIN_HEADER.size, 0)]
    for name, dtype, _ in VECTOR_ARRAYS:
        parts.append(np.ascontiguousarray(getattr(v, name), dtype=dtype).tobytes())
    binp = bundle / "vectors.bin"
    binp.write_bytes(b"".join(parts))
    return npz, binp


def read_vectors(bundle: Path) -> Vectors:
    path = Path(bundle) / "vectors.npz"
    try:
        with np.load(path) as z:
            arrays = {name: z[name] for name, _, _ in VECTOR_ARRAYS}
    except (KeyError, ValueError, OSError, EOFError) as e:
        raise InputError(f"{path}: cannot read test vectors ({type(e).__name__}: {e})") from None
    return Vectors(**arrays)


def read_vectors_bin(path: Path) -> dict[str, np.ndarray]:
    """Parse vectors.bin (used by tests to check it against vectors.npz)."""
    data = Path(path).read_bytes()
    if len(data) < BIN_HEADER.size:
        raise InputError(f"{path}: shorter than the vectors.bin header")
    magic, version, n, n_in, n_out, n_arr, hdr, _ = BIN_HEADER.unpack_from(data)
    if magic != BIN_MAGIC or version != BIN_VERSION or n_in != N_FEATURES or n_out != N_CLASSES:
        raise InputError(f"{path}: not a version-{BIN_VERSION} vectors.bin for {N_FEATURES} features")
    layout = bin_layout(n)
    if len(data) != layout["total_bytes"]:
        raise InputError(f"{path}: {len(data)} bytes, expected {layout['total_bytes']} for N={n}")
    return {
        a["name"]: np.frombuffer(data, dtype=a["dtype"], count=int(np.prod(a["shape"])), offset=a["offset"]).reshape(a["shape"])
        for a in layout["arrays"]
    }
