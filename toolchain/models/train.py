"""Supervised training with class-weighted cross-entropy (w_c = N / (C * n_c))."""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F
from tqdm.auto import tqdm

from ..data.contracts import N_CLASSES

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
) -> torch.nn.Module:
    """Adam on weighted CE. Give `epochs` (full passes) or `steps` (optimiser updates); `fused_adam`: see `adam`.

    Seeded: the same seed, data and initial model give the same result.
    """
    gen = torch.Generator().manual_seed(seed)
    xt = torch.as_tensor(np.asarray(x, dtype=np.float32))
    yt = torch.as_tensor(np.asarray(y, dtype=np.int64))
    w = class_weights(y) if weights is None else weights
    n = len(yt)
    batch_size = min(batch_size, n)
    per_epoch = (n + batch_size - 1) // batch_size
    total = steps if steps is not None else epochs * per_epoch
    opt = adam(model.parameters(), lr, fused=fused_adam)
    model.train()
    done = 0
    with torch.random.fork_rng():
        torch.manual_seed(seed)  # dropout masks
        bar = tqdm(total=total, desc=desc, leave=False, disable=desc is None)
        while done < total:
            order = torch.randperm(n, generator=gen)
            for i in range(0, n, batch_size):
                idx = order[i : i + batch_size]
                opt.zero_grad()
                loss = weighted_ce(model(xt[idx]), yt[idx], w)
                loss.backward()
                opt.step()
                done += 1
                bar.update(1)
                if done >= total:
                    break
        bar.close()
    model.eval()
    return model


@torch.no_grad()
def predict(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    model.eval()
    return model(torch.as_tensor(np.asarray(x, dtype=np.float32))).argmax(dim=1).numpy()
