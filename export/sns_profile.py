"""SN-S under the flat names of its own formats: the one place they map onto the network's blocks.

SN-S is the one-block case of the one network representation (quant.FloatNet / quant.QNet, hidden (30,)).
Its formats came before the layer table and stay byte for byte as they are, so that the images and headers
already on rovers keep loading: the format-1 image (image_layout.V1), the flat SN-S C headers (headers.py)
and an SN-S bundle's manifest entries and content hash (manifest.py). They name the arrays w1 b1 g bb w2 b2
gelu rsqrt_seed (w1 b1 gamma beta w2 b2 for the float model) and record the scheme in one flat dict of
scalars (`scalars`), where every other architecture records a list of blocks (QNet.scalars).
"""

from __future__ import annotations

import numpy as np

from fleetlab.data.contracts import N_CLASSES, N_FEATURES

from .quant import (C30, E_BITS, EPS_CAP, FEATURE_LSB, FZ, GELU_N, GELU_STEP_LOG2, H_BITS, N_HIDDEN, RSQRT_SEED_BITS,
                    SCHEME, FloatBlock, FloatNet, QBlock, QNet, row_bounds)
from fleetlab.errors import InputError

HIDDEN = (N_HIDDEN,)

# flat name -> (index of the block that holds it, or None for the network's own arrays; attribute)
Q_ARRAYS = {"w1": (0, "w"), "b1": (0, "b"), "g": (0, "g"), "bb": (0, "bb"), "w2": (None, "w_out"),
            "b2": (None, "b_out"), "gelu": (0, "gelu"), "rsqrt_seed": (None, "rsqrt_seed")}
F32_ARRAYS = {"w1": (0, "w"), "b1": (0, "b"), "gamma": (0, "gamma"), "beta": (0, "beta"), "w2": (None, "w_out"),
              "b2": (None, "b_out")}


def fits(net: QNet | FloatNet) -> bool:
    """Whether a network is an SN-S (and so is written in the SN-S formats)."""
    return net.hidden == HIDDEN


def _flat(net: QNet | FloatNet, names: dict[str, tuple[int | None, str]]) -> dict[str, np.ndarray]:
    if not fits(net):
        raise InputError(f"the SN-S formats need one hidden block of {N_HIDDEN} units, not {list(net.hidden)}")
    return {name: getattr(net if i is None else net.blocks[i], attr) for name, (i, attr) in names.items()}


def q_arrays(net: QNet) -> dict[str, np.ndarray]:
    """The integer arrays by their flat names, in the order of the SN-S formats."""
    return _flat(net, Q_ARRAYS)


def f32_arrays(fn: FloatNet) -> dict[str, np.ndarray]:
    """The float32 arrays by their flat names, in the order of the SN-S formats."""
    return _flat(fn, F32_ARRAYS)


def qnet(arrays: dict[str, np.ndarray], fg: int, fy: int, eps_m: int, eps_e: int, s1: float = float("nan"),
         s2: float = float("nan")) -> QNet:
    """The network of flat integer arrays and the block's scalars (a reader's: the scales are not stored, NaN)."""
    blk = QBlock(w=arrays["w1"], b=arrays["b1"], g=arrays["g"], bb=arrays["bb"], gelu=arrays["gelu"], fg=fg, fy=fy,
                 eps_m=eps_m, eps_e=eps_e, s=s1)
    return QNet([blk], arrays["w2"], arrays["b2"], s2, np.asarray(arrays["rsqrt_seed"]).astype(np.int64))


def float_net(arrays: dict[str, np.ndarray], eps: float) -> FloatNet:
    """The float network of flat float32 arrays."""
    blk = FloatBlock(arrays["w1"], arrays["b1"], arrays["gamma"], arrays["beta"])
    return FloatNet([blk], arrays["w2"], arrays["b2"], eps)


def scalars(net: QNet) -> dict:
    """The scheme's parameters that are not arrays, as an SN-S bundle records them (manifest.json and the
    content hash); the integer ones are members of the flat C model struct too."""
    q = q_arrays(net)
    blk = net.blocks[0]
    return {
        "scheme": SCHEME,
        "n_in": N_FEATURES,
        "n_hidden": N_HIDDEN,
        "n_out": N_CLASSES,
        "w1_max": int(np.abs(q["w1"]).max(initial=0)),
        "w2_max": int(np.abs(q["w2"]).max(initial=0)),
        "acc1_bound": int(row_bounds(q["w1"], q["b1"]).max(initial=0)),
        "acc2_bound": int(row_bounds(q["w2"], q["b2"]).max(initial=0)),
        "h_bits": H_BITS,
        "e_bits": E_BITS,
        "fz": FZ,
        "fg": int(blk.fg),
        "fy": int(blk.fy),
        "eps_m": int(blk.eps_m),
        "eps_e": int(blk.eps_e),
        "eps_cap": EPS_CAP,
        "gelu_step_log2": GELU_STEP_LOG2,
        "gelu_n": GELU_N,
        "rsqrt_seed_bits": RSQRT_SEED_BITS,
        "c30": C30,
        "s1": float(blk.s),
        "s2": float(net.s_out),
        "logit_scale": float(net.logit_scale),
        "feature_lsb": [float(v) for v in FEATURE_LSB],
    }
