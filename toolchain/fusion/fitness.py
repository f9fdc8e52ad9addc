"""Fitness of many candidate models on D_Cal: class-weighted cross-entropy, dropout off.

J(θ) = Σ_n w_{y_n} · (−log softmax(f_θ(x_n))_{y_n}) / Σ_n w_{y_n}, with w_c = N / (C · n_c)
(torch's weighted 'mean' reduction, the same loss the experts are trained with).
Lower is better.

`CalibrationFitness` evaluates P flat parameter vectors in one batched computation.
For SN-S it uses a specialised path that never materialises LayerNorm statistics
as separate passes: because LayerNorm normalises over the hidden units and the
first layer is linear, the centred pre-activation is x̃·(W̃ − mean_h W̃) and its
variance is the quadratic form x̃ᵀ G x̃ with G = W̃ᵀW̃/H (x̃ = [x − μ, 1], W̃ = [W, b + Wμ],
μ the calibration mean),
which is one small GEMM for all ants and rows. Other architectures use
`fleetlab.models.batched_logits`. Both agree with `SlipNet.eval()` to float rounding.
"""

from __future__ import annotations

import numpy as np
import torch

from ..data.contracts import N_CLASSES
from ..models import batched_logits
from ..models.mlp import LN_EPS, hidden_sizes, param_shapes
from ..models.train import class_weights


class CalibrationFitness:
    """Callable: flats (P, T) float32 -> weighted CE (P,) float32, one batched computation."""

    def __init__(self, arch: str, x: np.ndarray, y: np.ndarray, chunk: int = 100):
        x = np.asarray(x, dtype=np.float32)
        y = np.asarray(y, dtype=np.int64)
        if x.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[0] == 0:
            raise ValueError(f"calibration set must be (N, 12) features with N labels, got {x.shape} and {y.shape}")
        if not np.isfinite(x).all():
            raise ValueError("calibration features contain NaN or infinity")
        if y.min() < 0 or y.max() >= N_CLASSES:
            raise ValueError(f"calibration labels must be classes 0..{N_CLASSES - 1}, found {y.min()}..{y.max()}")
        self.arch = arch
        self.chunk = chunk
        self.x = torch.from_numpy(x)
        self.y = torch.from_numpy(y)
        self.class_weight = class_weights(y)
        self.weight_total = float(self.class_weight[self.y].sum())
        n = x.shape[0]
        # Centre the inputs (the shift goes into the bias, see _snS): raw features reach ~10²,
        # and centring keeps the float32 quadratic form for the variance well conditioned.
        self.mu = self.x.mean(dim=0)
        xt = torch.cat([self.x - self.mu, torch.ones(n, 1)], dim=1)  # x̃ = [x − μ, 1]
        self.xt_t = xt.T.contiguous()  # (13, N)
        self.xx = (xt[:, :, None] * xt[:, None, :]).reshape(n, -1).T.contiguous()  # (169, N)
        self.fast = len(hidden_sizes(arch)) == 1  # one hidden block: the closed-form path below
        self._kept: tuple[torch.Tensor, ...] | None = None  # the SN-S path's buffers, see _operands

    def __call__(self, flats: torch.Tensor) -> torch.Tensor:
        if flats.dim() == 1:
            flats = flats.unsqueeze(0)
        with torch.no_grad():
            parts = [
                self._snS(flats[i : i + self.chunk]) if self.fast else self._generic(flats[i : i + self.chunk])
                for i in range(0, flats.shape[0], self.chunk)
            ]
        return torch.cat(parts)

    def _loss(self, logits_t: torch.Tensor) -> torch.Tensor:
        """(P, 3, N) logits -> (P,) weighted CE: torch's per-row weighted CE, summed per ant / Σ w_{y_n}."""
        per_row = torch.nn.functional.cross_entropy(
            logits_t, self.y.expand(logits_t.shape[0], -1), weight=self.class_weight, reduction="none")
        return per_row.sum(dim=1).div_(self.weight_total)

    def _snS(self, vals: torch.Tensor) -> torch.Tensor:
        p, h = vals.shape[0], hidden_sizes(self.arch)[0]
        sizes = [torch.Size(shape).numel() for shape in param_shapes(self.arch)]
        w1, b1, g, beta, w2, b2 = torch.split(vals, sizes, dim=1)
        w1, w2 = w1.reshape(p, h, -1), w2.reshape(p, -1, h)
        b1 = b1 + w1 @ self.mu  # W x + b = W (x − μ) + (b + W μ)
        wa = torch.cat([w1, b1.unsqueeze(-1)], dim=-1)  # (P, H, 13)
        wc = wa - wa.mean(dim=1, keepdim=True)  # centred over hidden units
        gram = torch.bmm(wc.transpose(1, 2), wc).reshape(p, -1)  # (P, 169)
        inv_std = torch.mm(gram, self.xx).div_(h).add_(LN_EPS).rsqrt_().unsqueeze(1)  # (P, 1, N)
        # Scaling the (13, N) inputs per ant by 1/std costs a tenth of scaling the (H, N)
        # pre-activations, and β rides in the same GEMM as a 14th input that is always 1:
        # [γ ⊙ W̃c, β] @ [x̃ / std; 1] = γ ⊙ normalised + β in one pass.
        a, b, act = self._operands(p, h)
        k = self.xt_t.shape[0]
        torch.mul(wc, g.unsqueeze(-1), out=a[:, :, :k])
        a[:, :, k].copy_(beta)
        torch.mul(self.xt_t, inv_std, out=b[:, :k])
        torch.bmm(a, b, out=act)  # (P, H, N)
        torch.ops.aten.gelu_(act)
        logits = torch.baddbmm(b2.unsqueeze(-1), w2, act)  # (P, 3, N)
        return self._loss(logits)

    def _operands(self, p: int, h: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Views (p ≤ chunk) of three buffers kept for the whole search: the first layer's weights
        (p, H, 14), its inputs (p, 14, N) whose last row is 1 once and for all, and the activations
        (p, H, N).

        Why (issue 30): `torch.baddbmm(β, ...)` allocated a fresh (chunk, H, N) result every call
        (3.6 MB for 150 ants), paid the page faults of that memory and filled it with β through a
        broadcast copy, together as long as the GEMM itself; building the operands with `torch.cat`
        instead cost as much. Written into kept buffers, a 300-ant fitness call takes about 12 % less
        CPU, and gives the same bits as before on this machine (docs/scaling.md, "Profile and cuts").
        """
        k, n = self.xt_t.shape
        if self._kept is None or self._kept[0].shape[0] < p:
            rows = max(p, self.chunk)
            b = torch.empty(rows, k + 1, n)
            b[:, k].fill_(1.0)
            self._kept = (torch.empty(rows, h, k + 1), b, torch.empty(rows, h, n))
        return tuple(t[:p] for t in self._kept)

    def _generic(self, vals: torch.Tensor) -> torch.Tensor:
        return self._loss(batched_logits(self.arch, vals, self.x).transpose(1, 2))
