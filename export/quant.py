"""The fixed-point scheme of the estimator (integer-only inference for a core without FPU).

One representation serves every architecture: FloatNet (float32) and QNet (fixed point), a stack of
Linear -> LayerNorm -> GELU blocks (FloatBlock, QBlock) and a head. SN-S is the one-block case of width 30;
the steps below are written for it, and every other block uses the same steps with shifts that depend on
its width (docs/fixed_point.md, "A general block"), which at width 30 are the SN-S constants. The flat
names that SN-S's own formats give these arrays (w1, b1, ..., the format-1 image, the SN-S C headers) are
mapped onto the blocks in one place, sns_profile.py.

Full description with the overflow proofs: docs/fixed_point.md. The integer operations are
performed identically by `intref.py` (torch) and the C kernels (`firmware_c/src/slipest_infer_q.c`, `slipest_infer_table_q.c`).

Data flow for one window (all integers; Qn = value * 2^n):

1. Input: x_q int16 (12) in the raw LSB units of each channel (contracts.RAW_LSB).
2. Layer 1: h_i = b1_i + sum_j w1_ij * x_j (int32). w1 = round(W1_ij * LSB_j * s1) (int16): the
   per-feature LSB is folded into the weights and s1 is free because LayerNorm does not see the
   scale of its input. s1 is the largest scale whose exact worst case over all int16 inputs,
   max_i (2^15 sum_j |w1_ij| + |b1_i|), stays <= 2^31 - 2^8 (room for rounding shifts).
3. LayerNorm, integer (per sample):
   k1 = max(0, bitlen(max_i |h_i|) - 24);  h'_i = rsr(h_i, k1)          (|h'| <= 2^24)
   d_i = 30 h'_i - sum_j h'_j                                           (= 30 (h'_i - mean), exact)
   k2 = max(0, bitlen(max_i |d_i|) - 13);  e_i = rsr(d_i, k2)           (|e| <= 2^13)
   S = sum_i e_i^2                                                      (< 2^31)
   eps_S = EPS_M * 2^(EPS_E - 2(k1+k2)) rounded (0 / shift / capped at 2^30, cap counted)
   V = S + eps_S (uint32);  M = rsqrt_mult(V) ~ sqrt(30) 2^28 / sqrt(V)  (see below)
   z_i = rsr(e_i M, 16)                                                 (Q12, |z| < 22500)
   u_i = rsr(G_i z_i, 12 + FG - FY) + B_i, saturated to int16 (counted) (QFY)
   G = round(gamma 2^FG), B = round(beta 2^FY).
4. GELU by table: T[k] = round(GELU(-k/16) 2^FY), k = 0..128 (GELU(x) = x + GELU(-x) gives the
   positive side); v = |u|, k = v >> (FY-4), f = v & (2^(FY-4) - 1);
   t = 0 if k >= 128 else T[k] + rsr((T[k+1] - T[k]) f, FY - 4);  g = max(u, 0) + t   (QFY)
5. Head: logit_c = b2_c + sum_i w2_ci g_i (int32), w2 = round(W2 s2) (int16), b2 = round(b2 s2 2^FY),
   s2 the largest scale with max_c (2^15 sum_i |w2_ci| + |b2_c|) <= 2^31 - 1 (|g| < 2^15).
   Class = argmax, ties to the lowest index.

Rounding, defined once:
- rsr(x, k) ("right shift rounded") = floor((x + 2^(k-1)) / 2^k) for k >= 1, x for k = 0:
  round half up (towards +infinity). Every call site's bound leaves room for the + 2^(k-1).
  floor(x / 2^k) comes from a C helper (`asr32`: bias into uint32, shift, unbias) that is
  defined for negative numbers (a plain >> of a negative int is implementation-defined in C).
- Quantisation of real parameters (export time, in float64): round half away from zero.
- rsqrt_mult(V): V = 0 gives M = 0 (then every e_i = 0). Otherwise a = (32 - bitlen(V)) // 2,
  W = V 4^a in [2^30, 2^32); y0 = RSQRT_SEED[(W >> 27) - 8] (Q30 of 1/sqrt(w), w = W/2^32);
  two Newton steps with truncating (floor) shifts on non-negative 64-bit values:
  y2 = (y y) >> 30; t = ((W >> 2) y2) >> 30; y = (y (3 2^30 - t)) >> 31;
  M = ((y C30) << a + 2^31) >> 32 with C30 = round(sqrt(30) 2^14) (<= sqrt(30) 2^28 < 2^31).
  No division anywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from fleetlab.data.contracts import FEATURE_SOURCES, N_CLASSES, N_FEATURES, RAW_LSB
from fleetlab.models.mlp import LN_EPS, MAX_HIDDEN_LAYERS, MAX_UNITS, MIN_UNITS, SlipNet, arch_of
from fleetlab.errors import InputError

SCHEME = "fleetlab-slipest-q/1"
N_HIDDEN = 30  # SN-S: the width the constants below are written for

INT16_MIN, INT16_MAX = -(2**15), 2**15 - 1
INT32_MAX = 2**31 - 1
# Layer-1 accumulator limit: room for the rounding term 2^(k1-1) <= 2^6 of rsr(h, k1) in C.
ACC1_LIMIT = INT32_MAX - 2**8

W1_MAX = INT16_MAX  # int16 weights in every layer; the scale is limited by the exact per-row accumulator bound
H_BITS = 24  # |h'| <= 2^24 before centring
E_BITS = 13  # |e| <= 2^13 so that sum(e^2) over 30 units < 2^31
FZ = 12  # normalised activations z in Q12
GELU_STEP_LOG2 = 4  # table step 1/16
GELU_RANGE = 8  # table covers [-8, 0]
GELU_N = GELU_RANGE * 2**GELU_STEP_LOG2 + 1  # 129 entries
FY_MAX = 12
FY_MIN = GELU_STEP_LOG2
Z_BOUND = 5.5  # |z| <= sqrt(30) = 5.477 (+ rounding), used to choose FY
EPS_CAP = 2**30
RSQRT_SEED_BITS = 5  # seed table indexed by the top 5 bits of W (values 8..31)
C30 = round(math.sqrt(N_HIDDEN) * 2**14)

FEATURE_LSB = np.array([RAW_LSB[c] for c, _ in FEATURE_SOURCES], dtype=np.float64)


def rsqrt_seed_table() -> np.ndarray:
    """Q30 of 1/sqrt(w) at the centre of each bin w in [j/32, (j+1)/32), j = 8..31 (24 entries)."""
    j = np.arange(8, 32, dtype=np.float64)
    return np.array([round(2**30 / math.sqrt((k + 0.5) / 32)) for k in j], dtype=np.int64)


def _gelu(x: np.ndarray) -> np.ndarray:
    from scipy.special import erf

    return 0.5 * x * (1.0 + erf(x / math.sqrt(2.0)))


def gelu_table(fy: int) -> np.ndarray:
    v = np.arange(GELU_N, dtype=np.float64) / 2**GELU_STEP_LOG2
    return round_away(_gelu(-v) * 2**fy).astype(np.int16)


def round_away(x) -> np.ndarray:
    """Round half away from zero (float64 in, float64 out)."""
    x = np.asarray(x, dtype=np.float64)
    return np.sign(x) * np.floor(np.abs(x) + 0.5)


def _scale_for(max_abs: float, limit: float) -> float:
    return limit / max_abs if max_abs > 0 else 1.0


def row_bounds(w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact worst case |accumulator| per output row over all int16 inputs: 2^15 sum_j |w_ij| + |b_i|.

    Every left-to-right (or pairwise) partial sum is bounded by the same number."""
    return 2**15 * np.abs(w.astype(np.int64)).sum(axis=1) + np.abs(b.astype(np.int64))


def _fit_scale(wf: np.ndarray, bf: np.ndarray, w_max: int, limit: int, b_mult: float = 1.0) -> tuple[float, np.ndarray, np.ndarray]:
    """Largest scale s with max|round(wf s)| <= w_max and every row bound <= limit; returns (s, wq, bq).

    bq = round(bf * s * b_mult). Starts from the real-valued optimum and shrinks it until the
    rounded integers satisfy the bound (rounding can add up to 1/2 per element)."""
    per_row = 2**15 * np.abs(wf).sum(axis=1) + np.abs(bf) * b_mult
    s = min(_scale_for(np.abs(wf).max(), w_max), _scale_for(per_row.max(), limit))
    for _ in range(64):
        wq, bq = round_away(wf * s), round_away(bf * s * b_mult)
        if np.abs(wq).max(initial=0) <= w_max and row_bounds(wq, bq).max(initial=0) <= limit:
            return s, wq, bq
        s *= 0.999
    raise InputError("cannot fit the parameters into the accumulator bound")


def _mantissa_exponent(v: float) -> tuple[int, int]:
    """v ~= m * 2^e with m in [2^14, 2^15) (round half away from zero), or (0, 0) for v = 0."""
    if v <= 0:
        return 0, 0
    e = math.floor(math.log2(v)) - 14
    m = int(round_away(v / 2.0**e))
    if m >= 2**15:  # rounding carried into the next binade
        m, e = m // 2, e + 1
    return m, e


# --- The shifts of one block ----------------------------------------------------------------------------
#
# They depend only on its width H (docs/fixed_point.md, "A general block"); at H = 30 they are exactly
# SN-S's constants above, so SN-S bundles did not change when the general block came.


def h_bits_of(width: int) -> int:
    """Bits kept of h' before centring: |d| = |H h'_i - sum h'| <= 2 H 2^h_bits <= 2^30."""
    return min(H_BITS, 30 - (2 * width - 1).bit_length())


def e_bits_of(width: int) -> int:
    """Bits kept of the centred values: S = sum e^2 <= H 4^e_bits <= 2^31 (then V = S + eps < 2^32)."""
    e = E_BITS
    while width * 4**e > 2**31:
        e -= 1
    return e


def fz_of(width: int) -> int:
    """Fraction bits of z: |z| <= sqrt(H) 2^fz (1 + 2^-14) stays below 2^15 - 1, so that e M < 2^31 - 2^15."""
    f = FZ
    while math.sqrt(width) * 2**f * (1 + 2**-14) >= INT16_MAX:
        f -= 1
    return f


def c_of(width: int) -> int:
    """The normalising constant: M = c 2^14 / sqrt(V) = sqrt(H) 2^(fz + 16) / sqrt(V) (C30 at H = 30)."""
    return round(math.sqrt(width) * 2 ** (fz_of(width) + 2))


def acc_limit_of(width: int) -> int:
    """Bound of a block's accumulator: room for the rounding term 2^(k1 - 1) of rsr(h, k1), k1 <= 31 - h_bits."""
    return INT32_MAX - 2 ** (32 - h_bits_of(width))


def z_bound_of(width: int) -> float:
    """|z| <= sqrt(H - 1) < sqrt(H), rounded up to the next half (5.5 at H = 30): used to choose FY."""
    return math.ceil(2 * math.sqrt(width)) / 2


@dataclass
class FloatBlock:
    """One hidden block's float32 parameters: Linear (w, b), LayerNorm (gamma, beta)."""

    w: np.ndarray  # (H, n_in)
    b: np.ndarray  # (H,)
    gamma: np.ndarray  # (H,)
    beta: np.ndarray  # (H,)

    ARRAYS = ("w", "b", "gamma", "beta")


@dataclass
class FloatNet:
    """The float32 parameters of any SlipNet (eval semantics)."""

    blocks: list[FloatBlock]
    w_out: np.ndarray  # (3, H_last)
    b_out: np.ndarray  # (3,)
    eps: float = LN_EPS

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(int(b.w.shape[0]) for b in self.blocks)

    @classmethod
    def from_model(cls, model: SlipNet) -> "FloatNet":
        f = lambda t: t.detach().cpu().numpy().astype(np.float32).copy()  # noqa: E731
        arch_of(model)  # within the caps
        blocks = [FloatBlock(f(lin.weight), f(lin.bias), f(norm.weight), f(norm.bias))
                  for lin, norm in zip(model.linears, model.norms)]
        net = cls(blocks, f(model.head.weight), f(model.head.bias), float(np.float32(model.norms[0].eps)))
        for i, blk in enumerate(net.blocks):
            for name in FloatBlock.ARRAYS:
                if not np.isfinite(getattr(blk, name)).all():
                    raise InputError(f"model parameter {name} of hidden block {i + 1} contains NaN/Inf: cannot export")
        if not (np.isfinite(net.w_out).all() and np.isfinite(net.b_out).all()):
            raise InputError("model parameter of the output layer contains NaN/Inf: cannot export")
        return net

    def to_model(self) -> SlipNet:
        from fleetlab.models.mlp import SlipNet as Net

        m = Net(self.hidden)
        with torch.no_grad():
            for blk, lin, norm in zip(self.blocks, m.linears, m.norms):
                lin.weight.copy_(torch.from_numpy(blk.w))
                lin.bias.copy_(torch.from_numpy(blk.b))
                norm.weight.copy_(torch.from_numpy(blk.gamma))
                norm.bias.copy_(torch.from_numpy(blk.beta))
            m.head.weight.copy_(torch.from_numpy(self.w_out))
            m.head.bias.copy_(torch.from_numpy(self.b_out))
        return m.eval()


@dataclass
class QBlock:
    """One hidden block in fixed point. Its input is int16 (the features, or the previous block's
    GELU output in Q(fy) of that block: the requantisation between blocks is folded into w and b)."""

    w: np.ndarray  # int16 (H, n_in)
    b: np.ndarray  # int32 (H,)
    g: np.ndarray  # int16 (H,) LayerNorm gamma, Q(fg)
    bb: np.ndarray  # int32 (H,) LayerNorm beta, Q(fy)
    gelu: np.ndarray  # int16 (129,) GELU(-k/16) in Q(fy)
    fg: int
    fy: int
    eps_m: int
    eps_e: int
    s: float  # scale of the accumulator over the real pre-activation (information)

    INT_ARRAYS = ("w", "b", "g", "bb", "gelu")

    @property
    def width(self) -> int:
        return int(self.w.shape[0])

    @property
    def h_bits(self) -> int:
        return h_bits_of(self.width)

    @property
    def e_bits(self) -> int:
        return e_bits_of(self.width)

    @property
    def fz(self) -> int:
        return fz_of(self.width)

    @property
    def c(self) -> int:
        return c_of(self.width)

    def scalars(self) -> dict:
        return {
            "n_in": int(self.w.shape[1]), "width": self.width, "h_bits": self.h_bits, "e_bits": self.e_bits,
            "fz": self.fz, "fg": int(self.fg), "fy": int(self.fy), "eps_m": int(self.eps_m),
            "eps_e": int(self.eps_e), "c": self.c, "acc_bound": int(row_bounds(self.w, self.b).max(initial=0)),
            "acc_limit": acc_limit_of(self.width), "w_max": int(np.abs(self.w).max(initial=0)), "s": float(self.s),
        }

    def problems(self, n_in: int) -> list[str]:
        out = []
        if self.w.ndim != 2 or self.w.shape[1] != n_in or not MIN_UNITS <= self.width <= MAX_UNITS:
            out.append(f"weights of shape {self.w.shape} after {n_in} inputs")
            return out
        if any(np.shape(a) != (self.width,) for a in (self.b, self.g, self.bb)):
            out.append("bias or LayerNorm parameters of the wrong length")
        acc = int(row_bounds(self.w, self.b).max(initial=0))
        if acc > acc_limit_of(self.width):
            out.append(f"accumulator bound {acc} exceeds {acc_limit_of(self.width)}")
        if not FY_MIN <= self.fy <= FY_MAX:
            out.append(f"fy={self.fy} outside [{FY_MIN}, {FY_MAX}]")
        if not 0 <= self.fg <= 15:
            out.append(f"fg={self.fg} outside [0, 15]")
        if not 1 <= self.fz + self.fg - self.fy <= 30:
            out.append(f"u shift fz + fg - fy = {self.fz + self.fg - self.fy} outside [1, 30]")
        if np.abs(self.bb).max(initial=0) > INT16_MAX:
            out.append("LayerNorm beta does not fit int16 in Q(fy)")
        if not (2**14 <= self.eps_m < 2**15 or self.eps_m == 0) or abs(self.eps_e) > 200:
            out.append(f"eps mantissa/exponent {self.eps_m}, {self.eps_e} out of range")
        if len(self.gelu) != GELU_N:
            out.append(f"GELU table has {len(self.gelu)} entries, expected {GELU_N}")
        return out


@dataclass
class QNet:
    """Every integer array and every shift of the fixed-point path of any SlipNet."""

    blocks: list[QBlock]
    w_out: np.ndarray  # int16 (3, H_last)
    b_out: np.ndarray  # int32 (3,)
    s_out: float  # head weight scale; logits_real = logits_q / (s_out 2^fy_last)
    rsqrt_seed: np.ndarray = field(default_factory=rsqrt_seed_table)

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(b.width for b in self.blocks)

    @property
    def logit_scale(self) -> float:
        return self.s_out * 2.0 ** self.blocks[-1].fy

    def scalars(self) -> dict:
        """Every scalar of the scheme of this network, per block (manifest.json `quantization` and the content hash
        of a layer-table bundle; an SN-S bundle records the flat dict of sns_profile.scalars)."""
        return {
            "scheme": SCHEME, "n_in": N_FEATURES, "hidden": list(self.hidden), "n_out": N_CLASSES,
            "blocks": [b.scalars() for b in self.blocks],
            "head_w_max": int(np.abs(self.w_out).max(initial=0)),
            "head_acc_bound": int(row_bounds(self.w_out, self.b_out).max(initial=0)),
            "eps_cap": EPS_CAP, "gelu_step_log2": GELU_STEP_LOG2, "gelu_n": GELU_N, "rsqrt_seed_bits": RSQRT_SEED_BITS,
            "s_out": float(self.s_out), "logit_scale": float(self.logit_scale),
            "feature_lsb": [float(v) for v in FEATURE_LSB],
        }

    def check_bounds(self) -> None:
        """The preconditions of the overflow proof of every block; raise ValueError if broken."""
        problems = []
        if not 1 <= len(self.blocks) <= MAX_HIDDEN_LAYERS:
            problems.append(f"{len(self.blocks)} hidden blocks (1 to {MAX_HIDDEN_LAYERS} supported)")
        n_in = N_FEATURES
        for i, blk in enumerate(self.blocks):
            problems += [f"block {i + 1}: {p}" for p in blk.problems(n_in)]
            n_in = blk.width
        if self.w_out.shape != (N_CLASSES, n_in) or np.shape(self.b_out) != (N_CLASSES,):
            problems.append(f"head of shape {self.w_out.shape} after {n_in} units")
        elif int(row_bounds(self.w_out, self.b_out).max(initial=0)) > INT32_MAX:
            problems.append("head accumulator bound exceeds int32")
        if problems:
            raise InputError("fixed-point parameters break the scheme's bounds: " + "; ".join(problems))


def _quantize_block(fb: FloatBlock, w_scale: np.ndarray | float, b_mult: float, w_max: int,
                    eps: float) -> QBlock:
    """One block; the weights are first multiplied by w_scale (the feature LSBs for block 1, else 1) and
    the bias by b_mult (1 for block 1, else 2^fy of the block before: its input is in Q(fy))."""
    width = int(fb.w.shape[0])
    wp = fb.w.astype(np.float64) * w_scale
    s, wq, bq = _fit_scale(wp, fb.b.astype(np.float64), w_max, acc_limit_of(width), b_mult=b_mult)

    # LayerNorm affine: gamma in Q(fg), output in Q(fy) chosen so that |u| < 2^15 always.
    gamma, beta = fb.gamma.astype(np.float64), fb.beta.astype(np.float64)
    gmax = float(np.abs(gamma).max())
    if gmax >= 2**15:
        raise InputError(f"LayerNorm weight {gmax:g} too large for the fixed-point scheme")
    fg = 15 if gmax == 0 else min(15, math.floor(math.log2(INT16_MAX / gmax)))
    u_bound = float((np.abs(gamma) * z_bound_of(width) + np.abs(beta)).max())
    fy = FY_MAX
    while fy > FY_MIN and u_bound * 2**fy + 2 >= 2**15:
        fy -= 1
    if u_bound * 2**fy + 2 >= 2**15:
        raise InputError(f"LayerNorm output bound {u_bound:g} too large for the fixed-point scheme (needs < {2**15 / 2**FY_MIN:g})")

    # eps in the units of S = sum(e^2) before the per-sample shifts: eps H (H sigma)^2, sigma = s b_mult
    # the scale of the accumulator over the real pre-activation.
    sigma = s * b_mult
    eps_m, eps_e = _mantissa_exponent(eps * width * (width * sigma) ** 2)
    return QBlock(w=wq.astype(np.int16), b=bq.astype(np.int32), g=round_away(gamma * 2**fg).astype(np.int16),
                  bb=round_away(beta * 2**fy).astype(np.int32), gelu=gelu_table(fy), fg=fg, fy=fy,
                  eps_m=eps_m, eps_e=eps_e, s=float(s))


def quantize(fn: FloatNet, w_max: int = W1_MAX) -> QNet:
    """Float parameters of any SlipNet -> the fixed-point scheme, block by block, then the head (SN-S: one block)."""
    blocks: list[QBlock] = []
    w_scale, b_mult = FEATURE_LSB[None, :], 1.0  # block 1: the feature LSB folded into the weights
    for fb in fn.blocks:
        blocks.append(_quantize_block(fb, w_scale, b_mult, w_max, fn.eps))
        w_scale, b_mult = 1.0, 2.0 ** blocks[-1].fy  # later blocks: int16 input in Q(fy) of the block before
    # Head: logits in Q(s_out 2^fy); |g| <= 2^15 - 1 like an int16 input.
    s_out, woq, boq = _fit_scale(fn.w_out.astype(np.float64), fn.b_out.astype(np.float64), w_max, INT32_MAX,
                                 b_mult=b_mult)
    net = QNet(blocks, woq.astype(np.int16), boq.astype(np.int32), float(s_out))
    net.check_bounds()
    return net
