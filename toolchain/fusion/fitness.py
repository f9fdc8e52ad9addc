"""Fitness of many candidate models on D_Cal: class-weighted cross-entropy, dropout off.

J(θ) = Σ_n w_{y_n} · (−log softmax(f_θ(x_n))_{y_n}) / Σ_n w_{y_n}, with w_c = N / (C · n_c)
(torch's weighted 'mean' reduction, the same loss the experts are trained with).
Lower is better. With `targets` (each row's class probabilities t_nc, e.g. from its VO reading) only the
target changes: J = Σ_n w_{y_n} Σ_c t_nc (−log softmax(f_θ(x_n))_c) / Σ_n w_{y_n}, the row weights still
those of the labels y. One-hot targets are labels, and take the labels' path (the same bits).

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

import threading
import time

import numpy as np
import torch

from ..data.contracts import N_CLASSES
from ..models import batched_logits
from ..models.mlp import LN_EPS, hidden_sizes, param_shapes
from ..models.train import FC_RATE, GCE_Q, LOSSES, class_weights, log_transition_columns
from ..errors import InputError


class _Clock(threading.local):
    """Seconds this thread has spent in fitness calls (wall, and CPU of the whole process)."""

    wall_s = 0.0
    cpu_s = 0.0


_CLOCK = _Clock()


def fitness_seconds() -> tuple[float, float]:
    """Wall and process-CPU seconds spent in `CalibrationFitness` calls on this thread so far.

    Why: the fitness is the part of a search that a faster kernel could shorten, and everything
    else (ant construction, the updates, the other methods' training) is not. `evaluate` and
    `bench fusion` report both parts, so a speed goal can be checked against what the fitness
    alone could ever save (issue 30). Per thread, so runs on parallel threads keep their own."""
    return _CLOCK.wall_s, _CLOCK.cpu_s


SUB_CHUNK = 25  # ants per intra-op thread whose activations go from the first GEMM to the head together (piece_size)


def piece_size() -> int:
    """Ants per piece of the SN-S activations: SUB_CHUNK per intra-op thread.

    Why per thread: each GEMM and the GELU of a piece is split over the threads, which meet at a
    barrier after every step; with two threads, pieces of 25 spent a tenth of a 300-ant call at those
    barriers. Pieces of 50 on two threads take 11 % less time, and on one thread pieces of 25 stay the
    fastest. The numbers are the same in pieces of any size (docs/scaling.md, "Fifth pass")."""
    return SUB_CHUNK * max(1, torch.get_num_threads())


def _pieces(p: int, size: int) -> list[tuple[int, int]]:
    """[start, end) of ceil(p / size) pieces of p ants, as equal as can be: none is a lone ant unless p is 1."""
    count = max(1, -(-p // size))
    bounds = [p * i // count for i in range(count + 1)]
    return list(zip(bounds[:-1], bounds[1:]))


class CalibrationFitness:
    """Callable: flats (P, T) float32 -> weighted CE (P,) float32, one batched computation.

    `chunk` bounds the models per forward pass of the generic (deeper) path; the SN-S path takes
    any number at once and bounds its activations itself (piece_size)."""

    def __init__(self, arch: str, x: np.ndarray, y: np.ndarray, chunk: int = 100, loss: str = "ce",
                 noise_rate: float = FC_RATE, targets: np.ndarray | None = None):
        x = np.asarray(x, dtype=np.float32)
        y = np.asarray(y, dtype=np.int64)
        if x.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[0] == 0:
            raise InputError(f"calibration set must be (N, 12) features with N labels, got {x.shape} and {y.shape}")
        if not np.isfinite(x).all():
            raise InputError("calibration features contain NaN or infinity")
        if y.min() < 0 or y.max() >= N_CLASSES:
            raise InputError(f"calibration labels must be classes 0..{N_CLASSES - 1}, found {y.min()}..{y.max()}")
        if loss not in LOSSES:
            raise InputError(f"unknown fitness loss {loss!r}; choose one of {', '.join(LOSSES)}")
        targets = _checked_targets(targets, y, loss)
        if targets is not None and (targets[np.arange(y.shape[0]), y] == 1.0).all():  # each row certain of its label
            targets = None
        self.arch = arch
        self.chunk = chunk
        self.loss = loss  # 'ce', 'gce' (bounded) or 'fc' (forward-corrected), for noisy labels: models/train.py
        self.noise_rate = noise_rate  # the adjacent-noise rate ε that 'fc' assumes
        self.x = torch.from_numpy(x)
        self.y = torch.from_numpy(y)
        self.class_weight = class_weights(y)
        self.weight_total = float(self.class_weight[self.y].sum())
        # −t_nc w_{y_n} / Σ w_{y_n} in the (class, row) order of the logits: the loss is one matrix-vector product
        self.soft_coef = None if targets is None else torch.as_tensor(
            (-targets * self.class_weight[self.y].double().numpy()[:, None] / self.weight_total).T.reshape(-1),
            dtype=torch.float32)
        n = x.shape[0]
        # Centre the inputs (the shift goes into the bias, see _snS): raw features reach ~10²,
        # and centring keeps the float32 quadratic form for the variance well conditioned.
        self.mu = self.x.mean(dim=0)
        xt = torch.cat([self.x - self.mu, torch.ones(n, 1)], dim=1)  # x̃ = [x − μ, 1]
        self.xt_t = xt.T.contiguous()  # (13, N)
        self.xx = (xt[:, :, None] * xt[:, None, :]).reshape(n, -1).T.contiguous()  # (169, N)
        self.fast = len(hidden_sizes(arch)) == 1  # one hidden block: the closed-form path below
        self._kept: tuple[torch.Tensor, ...] | None = None  # the SN-S path's buffers, see _operands
        # The loss picks each row's own class out of the (P, 3·N) log-probabilities: flat index
        # y_n·N + n, and the per-row factor −w_{y_n} (what torch's weighted NLL multiplies by).
        self.picked = self.y * n + torch.arange(n)
        self.neg_row_weight = -self.class_weight[self.y]
        if loss == "fc":  # log T[i, y_n] (3, N), −inf where T is 0: added to log p before a logsumexp over i
            self.log_t_cols = log_transition_columns(noise_rate, self.y).contiguous()

    def __call__(self, flats: torch.Tensor) -> torch.Tensor:
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            return self._evaluate(flats)
        finally:
            _CLOCK.wall_s += time.perf_counter() - w0
            _CLOCK.cpu_s += time.process_time() - c0

    def _evaluate(self, flats: torch.Tensor) -> torch.Tensor:
        if flats.dim() == 1:
            flats = flats.unsqueeze(0)
        p = flats.shape[0]
        # A model's J is the same bits only within one call: MKL and OpenBLAS pick GEMM kernels by the
        # matrices' shapes and by the CPU, so the same model in a call of another size can differ in
        # its last bit (2 to 12 of 33 lone models did, on AMD Zen 2-4 and Intel Haswell; issue 42).
        # Nothing relies on more: AcoMerge gives ants that built one model the J of that model's row
        # of one call (`acomerge.evaluate_ants`). Across calls, sizes and CPUs J agrees to rounding.
        with torch.no_grad():
            if self.fast:  # one call: its activations are made in pieces anyway (_snS)
                return self._snS(flats)
            return torch.cat([self._generic(flats[i:j]) for i, j in _pieces(p, self.chunk)])

    def _loss(self, logits_t: torch.Tensor) -> torch.Tensor:
        """(P, 3, N) logits -> (P,) weighted CE: per row −w_{y_n}·log softmax(·)_{y_n}, summed per ant / Σ w_{y_n}
        (GCE or the forward-corrected CE in their place where `loss` says so).

        The same operations as torch's cross_entropy with weights and reduction 'none' (log_softmax
        over the classes, then the picked value times −w), so the same bits; picking with one
        `index_select` instead of the 2-D NLL kernel takes 40 % less time (issue 30)."""
        p = logits_t.shape[0]
        if self.soft_coef is not None:
            return torch.log_softmax(logits_t, dim=1).clamp_(min=-1e30).view(p, -1).mv(self.soft_coef)
        if self.loss == "fc":  # forward correction: log (Tᵀ p)_{y_n} = logsumexp_i (log p_i + log T[i, y_n])
            log_p = torch.logsumexp(torch.log_softmax(logits_t, dim=1).add_(self.log_t_cols), dim=1)
            return log_p.mul_(self.neg_row_weight).sum(dim=1).div_(self.weight_total)
        log_p = torch.log_softmax(logits_t, dim=1).view(p, -1).index_select(1, self.picked)
        if self.loss == "gce":  # w (1 − p^q) / q = −w (exp(q log p) − 1) / q
            log_p = log_p.mul_(GCE_Q).exp_().sub_(1.0).div_(GCE_Q)
        return log_p.mul_(self.neg_row_weight).sum(dim=1).div_(self.weight_total)

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
        size = piece_size()
        a, b, act, logits = self._operands(p, h, size)
        k = self.xt_t.shape[0]
        torch.mul(wc, g.unsqueeze(-1), out=a[:, :, :k])
        a[:, :, k].copy_(beta)
        torch.mul(self.xt_t, inv_std, out=b[:, :k])
        b2 = b2.unsqueeze(-1)
        # The activations of a few ants at a time, so that they stay in the L2 cache from the GEMM
        # through the GELU to the head's GEMM (150 ants' are 3.6 MB; the steps take
        # 12 % less time in pieces of about 25 per thread). Each ant's numbers do not depend on the
        # piece it is in, as long as no piece is a single ant of a larger call (a lone GEMM takes
        # another path in MKL).
        for i, j in _pieces(p, size):
            piece = act[: j - i]
            torch.bmm(a[i:j], b[i:j], out=piece)  # (piece, H, N)
            torch.ops.aten.gelu_(piece)
            torch.baddbmm(b2[i:j], w2[i:j], piece, out=logits[i:j])  # (piece, 3, N)
        return self._loss(logits)

    def _operands(self, p: int, h: int, size: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Views (p models) of four buffers kept for the whole search, grown to the largest call: the
        first layer's weights (p, H, 14), its inputs (p, 14, N) whose last row is 1 once and for all,
        the activations of one piece of ants (≤ `size`, H, N) and the logits (p, 3, N).

        Why (issue 30): `torch.baddbmm(β, ...)` allocated a fresh (chunk, H, N) result every call
        (3.6 MB for 150 ants), paid the page faults of that memory and filled it with β through a
        broadcast copy, together as long as the GEMM itself; building the operands with `torch.cat`
        instead cost as much. Written into kept buffers, a 300-ant fitness call takes about 12 % less
        CPU, and gives the same bits as before on this machine (docs/scaling.md, "Profile and cuts").
        """
        k, n = self.xt_t.shape
        if self._kept is None or self._kept[0].shape[0] < p or self._kept[2].shape[0] < min(p, size):
            rows = max(p, 0 if self._kept is None else self._kept[0].shape[0])  # the buffers only grow
            b = torch.empty(rows, k + 1, n)
            b[:, k].fill_(1.0)
            self._kept = (torch.empty(rows, h, k + 1), b, torch.empty(min(rows, size), h, n),
                          torch.empty(rows, N_CLASSES, n))
        a, b, act, logits = self._kept
        return a[:p], b[:p], act, logits[:p]

    def _generic(self, vals: torch.Tensor) -> torch.Tensor:
        return self._loss(batched_logits(self.arch, vals, self.x).transpose(1, 2))


def _checked_targets(targets: np.ndarray | None, y: np.ndarray, loss: str) -> np.ndarray | None:
    """Class probabilities per row (N, 3): non-negative, each row summing to 1."""
    if targets is None:
        return None
    t = np.asarray(targets, dtype=np.float64)
    if t.shape != (y.shape[0], N_CLASSES) or not np.isfinite(t).all() or (t < 0).any() \
            or not np.allclose(t.sum(axis=1), 1.0, atol=1e-6):
        raise InputError(f"calibration class probabilities must be ({y.shape[0]}, {N_CLASSES}) rows of non-negative "
                         f"numbers, each summing to 1")
    if loss != "ce":
        raise InputError(f"class probabilities are fitted with the cross-entropy; the {loss!r} loss takes hard labels")
    return t / t.sum(axis=1, keepdims=True)
