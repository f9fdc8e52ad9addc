"""Torch integer reference of the fixed-point scheme (quant.py, docs/fixed_point.md).

`IntSlipNet` runs the scheme on int64 tensors, operation by operation in the order of the C
kernels `firmware_c/src/slipest_infer_q.c` and `slipest_infer_table_q.c`; the C fixed-point path must reproduce its logits and
saturation counts bit for bit. Every intermediate is proven to fit the C type it lives in
(int32, or uint64 inside the reciprocal square root), so int64 here never wraps and the two
agree exactly. Floor division by a power of two replaces C's arithmetic-shift helper.
"""

from __future__ import annotations

import numpy as np
import torch

from .quant import EPS_CAP, GELU_N, GELU_STEP_LOG2, QBlock, QNet
from fleetlab.errors import InputError

_POW2 = torch.tensor([1 << b for b in range(63)], dtype=torch.int64)


def bitlen(m: torch.Tensor) -> torch.Tensor:
    """Number of bits of non-negative integers (0 -> 0, 1 -> 1, 2^k -> k+1)."""
    return (m.unsqueeze(-1) >= _POW2).sum(-1)


def rsr(x: torch.Tensor, k) -> torch.Tensor:
    """floor((x + 2^(k-1)) / 2^k), and x for k = 0: the scheme's rounding right shift (half up)."""
    k = torch.as_tensor(k, dtype=torch.int64)
    p = torch.bitwise_left_shift(torch.ones_like(k), k)
    return torch.div(x + p // 2, p, rounding_mode="floor")


def _saturate(x: torch.Tensor, lo: int, hi: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Clamp to [lo, hi]; also return the number of clamped values per row."""
    return x.clamp(lo, hi), ((x < lo) | (x > hi)).sum(-1)


class IntBlock(torch.nn.Module):
    """One Linear -> LayerNorm -> GELU block: int16-range input (N, n_in) -> int16-range g (N, H) in Q(fy)."""

    def __init__(self, blk: QBlock, rsqrt_seed: np.ndarray):
        super().__init__()
        self.width, self.h_bits, self.e_bits, self.fz, self.c = blk.width, blk.h_bits, blk.e_bits, blk.fz, blk.c
        self.fg, self.fy, self.eps_m, self.eps_e = int(blk.fg), int(blk.fy), int(blk.eps_m), int(blk.eps_e)
        for name in QBlock.INT_ARRAYS:  # t_<name>: the integer arrays as int64 tensors
            self.register_buffer("t_" + name, torch.as_tensor(np.asarray(getattr(blk, name), dtype=np.int64)))
        self.register_buffer("t_rsqrt_seed", torch.as_tensor(np.asarray(rsqrt_seed, dtype=np.int64)))

    def layer_norm(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Integer LayerNorm core: h (N,H) -> z (N,H) in Q(fz) (before gamma/beta), saturations (N,)."""
        k1 = (bitlen(h.abs().amax(1)) - self.h_bits).clamp(min=0).unsqueeze(1)
        hp = rsr(h, k1)
        d = self.width * hp - hp.sum(1, keepdim=True)  # H * (h' - mean(h')), exact
        k2 = (bitlen(d.abs().amax(1)) - self.e_bits).clamp(min=0).unsqueeze(1)
        e = rsr(d, k2)
        s = (e * e).sum(1, keepdim=True)

        # eps in the units of s: EPS_M * 2^(EPS_E - 2(k1+k2)), capped at 2^30 (counted).
        t = self.eps_e - 2 * (k1 + k2)
        m = torch.full_like(t, self.eps_m)
        up = torch.bitwise_left_shift(m, t.clamp(0, 15))
        down = rsr(m, (-t).clamp(1, 15))
        eps = torch.where(t >= 16, torch.full_like(t, EPS_CAP), torch.where(t >= 0, up, torch.where(t > -16, down, 0)))
        if self.eps_m == 0:
            eps = torch.zeros_like(eps)
        sat = ((t >= 16) & (self.eps_m != 0)).long().squeeze(1)
        v = s + eps

        mult = self.rsqrt_mult(v)
        z = rsr(e * mult, 16)  # |e M| <= sqrt(H) 2^(fz+16) (1 + 1e-5): |z| < 2^15, no saturation possible
        return z, sat

    def rsqrt_mult(self, v: torch.Tensor) -> torch.Tensor:
        """M ~ sqrt(H) 2^(fz+16) / sqrt(v) for v >= 0 (N,1), so that z = rsr(e M, 16); M = 0 when v = 0."""
        a = torch.where(v > 0, (32 - bitlen(v)) // 2, 0)
        w = torch.bitwise_left_shift(v, 2 * a)
        idx = (torch.bitwise_right_shift(w, 27) - 8).clamp(0, len(self.t_rsqrt_seed) - 1)
        y = self.t_rsqrt_seed[idx]
        w30 = torch.bitwise_right_shift(w, 2)
        for _ in range(2):  # Newton: y <- y (3 - w y^2) / 2, all values non-negative
            y2 = torch.bitwise_right_shift(y * y, 30)
            t = torch.bitwise_right_shift(w30 * y2, 30)
            y = torch.bitwise_right_shift(y * (3 * 2**30 - t), 31)
        m = torch.bitwise_right_shift(torch.bitwise_left_shift(y * self.c, a) + 2**31, 32)
        return torch.where(v > 0, m, 0)

    def gelu(self, u: torch.Tensor) -> torch.Tensor:
        """Table GELU in Q(fy): GELU(u) = max(u, 0) + GELU(-|u|), linear interpolation, step 1/16."""
        sh = self.fy - GELU_STEP_LOG2
        v = u.abs()
        k = torch.bitwise_right_shift(v, sh)
        f = torch.bitwise_and(v, (1 << sh) - 1)
        kk = k.clamp(max=GELU_N - 2)
        t0, t1 = self.t_gelu[kk], self.t_gelu[kk + 1]
        tneg = torch.where(k >= GELU_N - 1, 0, t0 + rsr((t1 - t0) * f, sh))
        return u.clamp(min=0) + tneg

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = x @ self.t_w.T + self.t_b
        z, sat = self.layer_norm(h)
        u, usat = _saturate(rsr(self.t_g * z, self.fz + self.fg - self.fy) + self.t_bb, -(2**15), 2**15 - 1)
        # g is the next block's int16 input as it is: the requantisation (to Q(fy) of this block) is
        # folded into the next block's weights and bias at export
        return self.gelu(u), sat + usat


class IntSlipNet(torch.nn.Module):
    """The fixed-point path of any SlipNet: int16 features (N,12) -> int32-range logits (N,3), saturations (N,)."""

    def __init__(self, net: QNet):
        super().__init__()
        net.check_bounds()
        self.blocks = torch.nn.ModuleList(IntBlock(b, net.rsqrt_seed) for b in net.blocks)
        self.register_buffer("t_w_out", torch.as_tensor(np.asarray(net.w_out, dtype=np.int64)))
        self.register_buffer("t_b_out", torch.as_tensor(np.asarray(net.b_out, dtype=np.int64)))

    def forward(self, xq: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = torch.as_tensor(xq).to(torch.int64)
        n_in = self.blocks[0].t_w.shape[1]
        if x.dim() != 2 or x.shape[1] != n_in:
            raise InputError(f"integer features must have shape (N, {n_in}), got {tuple(x.shape)}")
        if x.numel() and (x.min() < -(2**15) or x.max() > 2**15 - 1):
            raise InputError("integer features must be int16 values")
        sat = torch.zeros(x.shape[0], dtype=torch.int64)
        for blk in self.blocks:
            x, s = blk(x)
            sat = sat + s
        return x @ self.t_w_out.T + self.t_b_out, sat


def run(net: QNet, q_inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(logits int32 (N,3), saturations int32 (N,)) of the fixed-point path."""
    with torch.no_grad():
        logits, sat = IntSlipNet(net)(torch.from_numpy(np.asarray(q_inputs, dtype=np.int64)))
    return logits.numpy().astype(np.int32), sat.numpy().astype(np.int32)


def q_logits_of(net: QNet, q_inputs: np.ndarray, return_saturations: bool = False):
    """Integer logits (N,3) int32 of fixed-point parameters (of a bundle: `load_bundle(dir).qparams`;
    this module does not load bundles itself, so bundle -> vectors -> intref stays one-way)."""
    logits, sat = run(net, q_inputs)
    return (logits, sat) if return_saturations else logits


def argmax_lowest(logits: np.ndarray) -> np.ndarray:
    """Class of each row, ties to the lowest index (numpy's argmax already takes the first)."""
    return np.asarray(logits).argmax(axis=1).astype(np.int32)
