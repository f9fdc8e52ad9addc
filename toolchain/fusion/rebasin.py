"""Git Re-Basin weight matching (Ainsworth et al., 2023) for SN-S and SN-D.

Hidden units of an MLP can be reordered without changing its function: permute
the rows of a hidden Linear (weight and bias), the matching LayerNorm weight and
bias (LayerNorm's mean and variance are symmetric in the units, so they do not
change), and the columns of the next Linear. Weight matching picks, for each
model, the permutations that maximise the inner product of its weights with the
reference model's — equivalently minimise their L2 distance — layer by layer with
scipy's `linear_sum_assignment`, by coordinate descent over the hidden layers
until no permutation changes (one pass is exact for SN-S, which has one hidden layer).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

from ..models import SlipNet, flatten
from ..models.mlp import hidden_sizes, param_shapes
from ..errors import InputError

MAX_SWEEPS = 100


def _split(arch: str, flat: torch.Tensor) -> list[np.ndarray]:
    """Flat vector -> list of float64 arrays in flat order (see fleetlab.models.mlp)."""
    out, offset = [], 0
    v = flat.detach().to(torch.float64).cpu().numpy()
    for shape in param_shapes(arch):
        n = int(np.prod(shape))
        out.append(v[offset : offset + n].reshape(shape))
        offset += n
    if offset != v.size:
        raise InputError(f"flat vector has {v.size} values, {arch} has {offset} parameters")
    return out


def permute_flat(arch: str, flat: torch.Tensor, perms: list[np.ndarray]) -> torch.Tensor:
    """Apply hidden-unit permutations (new unit i = old unit perms[l][i]) to a flat vector.

    The result computes the same function as `flat`.
    """
    hidden = hidden_sizes(arch)
    if len(perms) != len(hidden) or any(len(p) != h for p, h in zip(perms, hidden)):
        raise InputError(f"{arch} needs permutations of sizes {hidden}")
    params = _split(arch, flat)
    out = []
    prev = np.arange(params[0].shape[1])  # input features are never permuted
    for layer, perm in enumerate(perms):
        w, b, g, beta = params[4 * layer : 4 * layer + 4]
        out += [w[perm][:, prev], b[perm], g[perm], beta[perm]]
        prev = perm
    w_out, b_out = params[-2:]
    out += [w_out[:, prev], b_out]
    return torch.tensor(np.concatenate([p.reshape(-1) for p in out]), dtype=flat.dtype)


def _match_layer(ref: list[np.ndarray], other: list[np.ndarray], perms: list[np.ndarray], layer: int) -> np.ndarray:
    """Best permutation of hidden layer `layer`, the other layers' permutations held fixed."""
    n_hidden = len(perms)
    w_r, b_r, g_r, beta_r = ref[4 * layer : 4 * layer + 4]
    w_o, b_o, g_o, beta_o = other[4 * layer : 4 * layer + 4]
    prev = perms[layer - 1] if layer > 0 else np.arange(w_o.shape[1])
    score = w_r @ w_o[:, prev].T + np.outer(b_r, b_o) + np.outer(g_r, g_o) + np.outer(beta_r, beta_o)
    # outgoing weights: the next layer (or the head), its rows already permuted
    nxt_r = ref[4 * (layer + 1)] if layer + 1 < n_hidden else ref[-2]
    nxt_o = other[4 * (layer + 1)] if layer + 1 < n_hidden else other[-2]
    rows = perms[layer + 1] if layer + 1 < n_hidden else np.arange(nxt_o.shape[0])
    score += nxt_r.T @ nxt_o[rows]
    _, cols = linear_sum_assignment(score, maximize=True)
    return cols


def match_permutations(arch: str, ref_flat: torch.Tensor, flat: torch.Tensor) -> list[np.ndarray]:
    """Permutations that bring `flat` closest to `ref_flat` (coordinate descent over layers)."""
    ref, other = _split(arch, ref_flat), _split(arch, flat)
    perms = [np.arange(h) for h in hidden_sizes(arch)]
    for _ in range(MAX_SWEEPS):
        changed = False
        for layer in range(len(perms)):
            new = _match_layer(ref, other, perms, layer)
            if not np.array_equal(new, perms[layer]):
                perms[layer], changed = new, True
        if not changed or len(perms) == 1:
            break
    return perms


def align_to_reference(models: list[SlipNet], arch: str, reference: int = 0) -> list[torch.Tensor]:
    """Flat parameter vectors of `models`, each permuted to match models[reference].

    The reference comes back unchanged; every model computes the same function as before.
    """
    if not models:
        raise InputError("no models to align")
    if not 0 <= reference < len(models):
        raise InputError(f"reference index {reference} out of range for {len(models)} models")
    flats = [flatten(m) for m in models]
    ref = flats[reference]
    return [
        f.clone() if i == reference else permute_flat(arch, f, match_permutations(arch, ref, f))
        for i, f in enumerate(flats)
    ]
