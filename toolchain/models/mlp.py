"""SN-S, SN-D and any other stack of hidden blocks (docs/architecture.md, contract 3), and the flat-parameter
view used by fusion. An architecture is a string: "sn-s", "sn-d", or hidden sizes such as "64,32".

Flat order is `model.parameters()` order: for each hidden block Linear.weight,
Linear.bias, LayerNorm.weight, LayerNorm.bias; then the output Linear.weight,
Linear.bias. SN-S has 543 parameters, SN-D 12,547.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from ..data.contracts import N_CLASSES, N_FEATURES
from ..errors import InputError

ARCHS: dict[str, tuple[int, ...]] = {"sn-s": (30,), "sn-d": (128, 64, 32)}
# Any other architecture is written as its hidden sizes, "64,32". The caps are those of the
# fixed-point scheme and the C kernel (docs/fixed_point.md); a C build may lower them
# (SLIPEST_MAX_LAYERS, SLIPEST_MAX_WIDTH), never raise them.
MAX_HIDDEN_LAYERS = 4
MIN_UNITS, MAX_UNITS = 2, 256
DROPOUT = 0.2  # paper; dropout follows the first hidden block only
LN_EPS = 1e-5


class SlipNet(nn.Module):
    def __init__(self, hidden: tuple[int, ...], dropout: float = DROPOUT):
        super().__init__()
        self.hidden = tuple(hidden)
        dims = (N_FEATURES, *self.hidden)
        self.linears = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.norms = nn.ModuleList(nn.LayerNorm(h, eps=LN_EPS) for h in self.hidden)
        self.dropout = nn.Dropout(dropout)
        self.head = nn.Linear(self.hidden[-1], N_CLASSES)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for i, (lin, norm) in enumerate(zip(self.linears, self.norms)):
            x = F.gelu(norm(lin(x)))
            if i == 0:
                x = self.dropout(x)
        return self.head(x)

    def parameters(self, recurse: bool = True):  # fixed flat order, see module docstring
        for lin, norm in zip(self.linears, self.norms):
            yield from (lin.weight, lin.bias, norm.weight, norm.bias)
        yield from (self.head.weight, self.head.bias)


def hidden_sizes(arch: str) -> tuple[int, ...]:
    """Hidden widths of an architecture: a name of ARCHS or comma-separated sizes such as "64,32"."""
    if arch in ARCHS:
        return ARCHS[arch]
    try:
        sizes = tuple(int(t) for t in str(arch).split(","))
    except ValueError:
        sizes = ()
    if not sizes:
        raise InputError(f"unknown architecture {arch!r}: give {' or '.join(ARCHS)}, or hidden sizes such as 64,32")
    if len(sizes) > MAX_HIDDEN_LAYERS or any(not MIN_UNITS <= h <= MAX_UNITS for h in sizes):
        raise InputError(f"architecture {arch!r}: 1 to {MAX_HIDDEN_LAYERS} hidden layers of "
                         f"{MIN_UNITS} to {MAX_UNITS} units are supported")
    return sizes


def arch_name(hidden: tuple[int, ...]) -> str:
    """The canonical name of hidden sizes: sn-s / sn-d, or "64,32" (what metadata and bundles record)."""
    for name, sizes in ARCHS.items():
        if sizes == tuple(hidden):
            return name
    return ",".join(str(h) for h in hidden)


def canonical_arch(arch: str) -> str:
    """Validate an --arch value and return its canonical name ("30" -> "sn-s", " 64, 32" -> "64,32")."""
    return arch_name(hidden_sizes(arch))


def arch_of(model: SlipNet) -> str:
    return canonical_arch(arch_name(model.hidden))


def build(arch: str, seed: int | None = None) -> SlipNet:
    hidden = hidden_sizes(arch)
    if seed is not None:
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            return SlipNet(hidden)
    return SlipNet(hidden)


def param_shapes(arch: str) -> list[tuple[int, ...]]:
    dims = (N_FEATURES, *hidden_sizes(arch))
    shapes: list[tuple[int, ...]] = []
    for a, b in zip(dims[:-1], dims[1:]):
        shapes += [(b, a), (b,), (b,), (b,)]
    return shapes + [(N_CLASSES, dims[-1]), (N_CLASSES,)]


def n_params(arch: str) -> int:
    return sum(torch.Size(s).numel() for s in param_shapes(arch))


def flatten(model: SlipNet) -> torch.Tensor:
    return torch.cat([p.detach().reshape(-1) for p in model.parameters()])


def load_flat(model: SlipNet, vec: torch.Tensor) -> SlipNet:
    """Copy a flat vector into the model's parameters (in place) and return the model."""
    vec = torch.as_tensor(vec)
    total = sum(p.numel() for p in model.parameters())
    if vec.numel() != total:
        raise InputError(f"flat vector has {vec.numel()} values, model has {total} parameters")
    offset = 0
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(vec[offset : offset + p.numel()].view_as(p))
            offset += p.numel()
    return model


def _unflatten(arch: str, flat: torch.Tensor) -> list[torch.Tensor]:
    """(P, T) -> list of (P, *shape) views in flat order."""
    out, offset = [], 0
    for shape in param_shapes(arch):
        n = torch.Size(shape).numel()
        out.append(flat[:, offset : offset + n].reshape(flat.shape[0], *shape))
        offset += n
    return out


def batched_logits(arch: str, flat: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Logits of P models in one computation: (P, T), (N, 12) -> (P, N, 3); with x (P, N, 12),
    model p sees its own inputs x[p] (several calibration sets in one batch).

    Inference semantics (dropout off), identical to SlipNet.eval() up to float rounding.
    """
    if flat.dim() == 1:
        flat = flat.unsqueeze(0)
    params = _unflatten(arch, flat)
    h = x if x.dim() == 3 else x.unsqueeze(0).expand(flat.shape[0], *x.shape)
    n_hidden = len(hidden_sizes(arch))
    for i in range(n_hidden):
        w, b, g, beta = params[4 * i : 4 * i + 4]
        h = torch.baddbmm(b.unsqueeze(1), h, w.transpose(1, 2))
        mu = h.mean(dim=-1, keepdim=True)
        var = h.var(dim=-1, unbiased=False, keepdim=True)
        h = (h - mu) * torch.rsqrt(var + LN_EPS) * g.unsqueeze(1) + beta.unsqueeze(1)
        h = F.gelu(h)
    w, b = params[-2:]
    return torch.baddbmm(b.unsqueeze(1), h, w.transpose(1, 2))
