"""Supervised training with class-weighted cross-entropy (w_c = N / (C * n_c))."""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F
from tqdm.auto import tqdm

from ..data.contracts import N_CLASSES
from ..errors import InputError

# Expert training hyper-parameters (paper's reference setup).
EXPERT_LR = 0.0035
EXPERT_BATCH = 32
EXPERT_EPOCHS = 70


def class_weights(y: np.ndarray, n_classes: int = N_CLASSES) -> torch.Tensor:
    """w_c = N / (C * n_c); a class absent from y gets weight 0 (it cannot be fitted)."""
    counts = np.bincount(np.asarray(y), minlength=n_classes).astype(np.float64)
    w = np.where(counts > 0, len(y) / (n_classes * np.maximum(counts, 1)), 0.0)
    return torch.tensor(w, dtype=torch.float32)


def adam(params, lr: float, fused: bool = False) -> torch.optim.Adam:
    """The Adam of every training here; `fused`: torch's fused CPU kernel (one call per step).

    Why fused for the per-run calibration work (fine-tuning, distillation, AdaMerging; issue 30): the
    models are small (SN-S: 543 parameters in 6 tensors), so the per-tensor Adam spends most of its
    step in Python and dispatch; fused, a 130-step SN-S fine-tuning takes about 23 % less CPU. It rounds
    a little differently (parameters within about 3e-7 after 130 steps); its AVX2 and AVX-512 kernels
    give the same bits. Why not for the source models (experts, joint model, the example bundle):
    they are every search's input, and trained once; kept bit for bit, the AcoMerge family's tables
    stay exactly as they were (docs/scaling.md, "Profile and cuts").
    """
    return torch.optim.Adam(params, lr=lr, fused=fused)


def weighted_ce(logits: torch.Tensor, y: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Class-weighted cross-entropy, mean over weights (torch's 'mean' reduction)."""
    return F.cross_entropy(logits, y, weight=weights)


# The losses a calibration step can use: cross-entropy, or the generalised cross-entropy of Zhang & Sabuncu
# (NeurIPS 2018), L_q = (1 − p_y^q) / q. Why GCE for noisy calibration labels (issue 46): it is bounded (a
# confidently "wrong" label, often a mislabelled one, costs at most 1/q instead of an unbounded −log p), it
# needs no estimate of the noise rate or of a transition matrix (D_Cal's 150 rows could not give one), and
# with q = 0.7 (the paper's choice) it keeps most of CE's gradient on rows the model is unsure of.
#
# 'fc' is forward loss correction (Patrini et al., CVPR 2017): the model's class probabilities p are pushed
# through the label-noise transition matrix T (T[i, j] = P(observed label j | true class i)) before the
# log-likelihood of the observed label is taken, −log (Tᵀp)_ỹ. In expectation over noisy labels (unweighted) its
# optimum is the p of the exact labels' posterior. Why this T (issue 46): calibration labels come from visual
# odometry, whose errors move a window's slip across one threshold, never two, so T is the adjacent-class
# matrix (`adjacent_transition`): its structure is known, and one number, the assumed rate ε, is left. Measured,
# it does not close the gap that 20 % adjacent noise opens (docs/paper_table.md, "Noisy calibration labels").
LOSSES = ("ce", "gce", "fc")
GCE_Q = 0.7
FC_RATE = 0.2  # the ε that 'fc' assumes by default (docs/paper_table.md, "Noisy calibration labels")


def check_noise_rate(rate: float, what: str = "assumed label-noise rate") -> None:
    """The one bound of an assumed adjacent-noise rate ε: [0, 1) (at 1 no label would be kept)."""
    if not 0.0 <= rate < 1.0:
        raise InputError(f"{what} must lie in [0, 1), got {rate}")


def adjacent_transition(rate: float, n_classes: int = N_CLASSES) -> torch.Tensor:
    """(C, C) T[i, j] = P(label j | true class i) of `adjacent:rate` noise (data/label_noise.py): the label stays
    with 1 − rate, else moves one class up or down (an inner class either way, half each)."""
    check_noise_rate(rate)
    t = torch.zeros(n_classes, n_classes, dtype=torch.float64)
    for i in range(n_classes):
        neighbours = [j for j in (i - 1, i + 1) if 0 <= j < n_classes]
        t[i, i] = 1.0 - rate
        for j in neighbours:
            t[i, j] = rate / len(neighbours)
    return t.to(torch.float32)


def log_transition_columns(rate: float, y: torch.Tensor, n_classes: int = N_CLASSES) -> torch.Tensor:
    """(C, N) log T[i, y_n], −inf where T is 0: what forward correction adds to log p_i before a logsumexp over i."""
    return adjacent_transition(rate, n_classes).log()[:, y]


def corrected_log_prob(log_p: torch.Tensor, y: torch.Tensor, rate: float) -> torch.Tensor:
    """(N,) log (Tᵀ p)_{y_n} of forward correction from (N, C) log-probabilities: log Σ_i T[i, y_n] p_i as a
    logsumexp of log T[i, y_n] + log p_i, finite where p_{y_n} underflows. Rate 0 gives log p_{y_n} itself."""
    log_t = log_transition_columns(rate, y, log_p.shape[1]).to(log_p.dtype)
    return torch.logsumexp(log_p + log_t.T, dim=1)


def weighted_gce(logits: torch.Tensor, y: torch.Tensor, weights: torch.Tensor, q: float = GCE_Q) -> torch.Tensor:
    """Class-weighted generalised cross-entropy: Σ w_y (1 − p_y^q) / q / Σ w_y (p_y^q as exp(q log p_y))."""
    log_p = torch.log_softmax(logits, dim=1).gather(1, y.unsqueeze(1)).squeeze(1)
    w = weights[y]
    return (w * (1.0 - torch.exp(q * log_p)) / q).sum() / w.sum()


def weighted_forward_ce(logits: torch.Tensor, y: torch.Tensor, weights: torch.Tensor,
                        rate: float = FC_RATE) -> torch.Tensor:
    """Class-weighted forward-corrected cross-entropy Σ w_y (−log (Tᵀ softmax(logits))_y) / Σ w_y, with T the
    adjacent-noise matrix at `rate`."""
    log_q = corrected_log_prob(torch.log_softmax(logits, dim=1), y, rate)
    w = weights[y]
    return -(w * log_q).sum() / w.sum()


def weighted_loss(name: str, logits: torch.Tensor, y: torch.Tensor, weights: torch.Tensor,
                  noise_rate: float = FC_RATE) -> torch.Tensor:
    """`name` in LOSSES; `noise_rate`: the ε that 'fc' assumes."""
    if name == "fc":
        return weighted_forward_ce(logits, y, weights, noise_rate)
    if name == "gce":
        return weighted_gce(logits, y, weights)
    if name == "ce":
        return weighted_ce(logits, y, weights)
    raise InputError(f"unknown loss {name!r}; choose one of {', '.join(LOSSES)}")


def train_classifier(
    model: torch.nn.Module,
    x: np.ndarray,
    y: np.ndarray,
    *,
    epochs: int | None = EXPERT_EPOCHS,
    steps: int | None = None,
    lr: float = EXPERT_LR,
    batch_size: int = EXPERT_BATCH,
    seed: int = 0,
    weights: torch.Tensor | None = None,
    desc: str | None = None,
    fused_adam: bool = False,
    device: str = "cpu",
    loss: str = "ce",
    noise_rate: float = FC_RATE,
) -> torch.nn.Module:
    """Adam on weighted CE (or `loss` 'gce', or 'fc' assuming adjacent noise at `noise_rate`). Give `epochs`
    (full passes) or `steps` (optimiser updates); `fused_adam`: see `adam`.

    Seeded: the same seed, data and initial model give the same result. `device`: 'cpu' (the
    reference) or a CUDA device, where each step is one replayed CUDA graph (`_CapturedSteps`); the
    batches are the same, the dropout masks come from the GPU's generator and the GPU rounds
    differently, so a GPU-trained model is another (equally good) model, not the CPU's bit for bit.
    The model is returned on the CPU, in eval mode.
    """
    gen = torch.Generator().manual_seed(seed)
    xt = torch.as_tensor(np.asarray(x, dtype=np.float32))
    yt = torch.as_tensor(np.asarray(y, dtype=np.int64))
    w = class_weights(y) if weights is None else weights
    n = len(yt)
    batch_size = min(batch_size, n)
    per_epoch = (n + batch_size - 1) // batch_size
    total = steps if steps is not None else epochs * per_epoch
    if loss not in LOSSES or (loss != "ce" and device != "cpu"):
        raise InputError(f"loss {loss!r}: one of {', '.join(LOSSES)}, and only 'ce' on a GPU")
    model.train()
    gpu = None if device == "cpu" else torch.device(device)
    forked = None if gpu is None else [gpu.index if gpu.index is not None else torch.cuda.current_device()]
    with torch.random.fork_rng(devices=forked):
        torch.manual_seed(seed)  # dropout masks
        bar = tqdm(total=total, desc=desc, leave=False, disable=desc is None)
        if gpu is None:
            opt = adam(model.parameters(), lr, fused=fused_adam)
            for idx in _batches(n, batch_size, total, gen):
                opt.zero_grad()
                weighted_loss(loss, model(xt[idx]), yt[idx], w, noise_rate).backward()
                opt.step()
                bar.update(1)
        else:
            steps_on = _CapturedSteps(model.to(gpu), xt.to(gpu), yt.to(gpu), w.to(gpu), lr)
            for idx in _batches(n, batch_size, total, gen):
                steps_on.step(idx)
                bar.update(1)
            model.to("cpu")
        bar.close()
    model.eval()
    return model


def _batches(n: int, batch_size: int, total: int, gen: torch.Generator):
    """The row indices of `total` optimiser steps: a fresh permutation of the n rows per epoch,
    cut into batches (an epoch's last batch is shorter when batch_size does not divide n)."""
    done = 0
    while done < total:
        order = torch.randperm(n, generator=gen)
        for i in range(0, n, batch_size):
            yield order[i : i + batch_size]
            done += 1
            if done >= total:
                return


class _CapturedSteps:
    """Training steps on a CUDA device, each one replay of a CUDA graph.

    Why: a step of these small models is some hundred tiny kernels; launched one by one from
    Python the GPU is slower than one CPU thread, captured and replayed it is 4-10x faster
    (scripts/gpu_training_probe.py, docs/scaling.md). The graph holds forward, loss, backward and
    Adam's update (capturable=True: its step count lives on the GPU) for a fixed batch size, with
    the batch's row indices as its one input; an epoch's shorter last batch gets a graph of its own.
    The first steps run eagerly on a side stream, as real training steps: they allocate Adam's
    state and warm cuBLAS up before any capture, as CUDA graphs require.
    """

    WARM_UP_STEPS = 3

    def __init__(self, model: torch.nn.Module, xt: torch.Tensor, yt: torch.Tensor, w: torch.Tensor, lr: float):
        self.model, self.xt, self.yt, self.w = model, xt, yt, w
        self.opt = torch.optim.Adam(model.parameters(), lr=lr, capturable=True)
        self.graphs: dict[int, tuple[torch.cuda.CUDAGraph, torch.Tensor]] = {}
        self.eager_left = self.WARM_UP_STEPS

    def _loss(self, idx: torch.Tensor) -> torch.Tensor:
        return weighted_ce(self.model(self.xt[idx]), self.yt[idx], self.w)

    def step(self, idx: torch.Tensor) -> None:
        idx = idx.to(self.xt.device)
        if self.eager_left > 0:
            self.eager_left -= 1
            side = torch.cuda.Stream(self.xt.device)
            side.wait_stream(torch.cuda.current_stream(self.xt.device))
            with torch.cuda.stream(side):
                self.opt.zero_grad(set_to_none=True)
                self._loss(idx).backward()
                self.opt.step()
            torch.cuda.current_stream(self.xt.device).wait_stream(side)
            return
        if len(idx) not in self.graphs:
            self.graphs[len(idx)] = self._capture(len(idx))
        graph, static_idx = self.graphs[len(idx)]
        static_idx.copy_(idx)
        graph.replay()

    def _capture(self, size: int) -> tuple[torch.cuda.CUDAGraph, torch.Tensor]:
        """Record (not run) one step for batches of `size` rows; the gradients are the graph's own
        tensors, written (not accumulated) by every replay."""
        static_idx = torch.zeros(size, dtype=torch.int64, device=self.xt.device)
        graph = torch.cuda.CUDAGraph()
        self.opt.zero_grad(set_to_none=True)
        with torch.cuda.graph(graph):
            self._loss(static_idx).backward()
            self.opt.step()
        return graph, static_idx


@torch.no_grad()
def predict(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    model.eval()
    return model(torch.as_tensor(np.asarray(x, dtype=np.float32))).argmax(dim=1).numpy()
