"""How far two correct float32 evaluations of a bundle's network may lie apart: the tolerance of every float check.

torch (the vectors' `torch_logits`), onnxruntime (`model.onnx`) and the C float path (`slipest_infer_f32`) evaluate
the same network with the same float32 parameters on the same float32 inputs, each in its own order of operations.
None of them is exact, but each stays within a forward error bound E of the exact (real-arithmetic) result, so two
of them differ by at most 2E. `float_bound` computes E for every logit of every given input; `float_tolerance` turns
it into the one number a bundle records (manifest.json `float_tolerance`), which every float check reads: the ONNX
check and `fleetlab export --check`, the C vector checks (CMake reads it from the manifest), the Python tests.

The bound (docs/fixed_point.md, "The float path: tolerance") is the first-order forward error bound
E_c = sum over every rounded intermediate q of |d logit_c / d q| * rho_q, where rho_q bounds the rounding error that
computing q from its (exact) operands adds, and the derivatives are those of the exact network, evaluated in float64
by autograd. With u = 2^-24 and gamma_n = n u / (1 - n u), per hidden block of width H with n inputs a:

* Linear h = W a + b:           rho_h = gamma_(n+1) (|W| |a| + |b|)          (any summation order, FMA or not)
* mean mu of h:                 rho_mu = gamma_(H+1) mean |h|
* variance v (two-pass, Welford or pairwise moments, or double accumulation):
                                rho_v = 2 gamma_(H+3) sqrt(mean(h^2) v) + rho_mu^2
* r = 1 / sqrt(v + eps):        rho_r = 5 u r                                (add, sqrt, reciprocal, eps in float32)
* z = (h - mu) r, also computed as h r - mu r:
                                rho_z = 3 u (|h| + |mu|) r + u |z|
* y = gamma z + beta:           rho_y = gamma_2 (|gamma z| + |beta|)
* GELU g(y):                    rho_g = GELU_REL |y|                         (assumption on each runtime, measured)
* head logits = W g + b:        rho = gamma_(n+1) (|W| |g| + |b|)

Rule: |a - b| <= tolerance * max(1, |torch logit|) for every logit of every vector, with
tolerance = max over the vectors' logits of 2 E / max(1, |logit|), rounded up to 3 significant digits.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch.nn import functional as F

U = 2.0 ** -24  # unit roundoff of float32 (round to nearest)
# |computed GELU(y) - GELU(y)| <= GELU_REL |y| for every runtime (an assumption; tests/test_float_tolerance.py measures
# it: torch 2.13's F.gelu 6.0 u, onnxruntime's Div/Erf/Add/Mul graph 1.9 u, the C form with slipest_erf_f32 < 3 u)
GELU_REL = 12 * U
RULE = ("|a - b| <= tolerance * max(1, |torch logit|) for every logit of every test vector; a, b: any two of torch, "
        "onnxruntime, the C float path")
DERIVATION = ("tolerance = max over the vectors' logits of 2 E / max(1, |logit|), rounded up to 3 significant digits; "
              "E = first-order float32 forward error bound of one evaluation: the rounding bound of every intermediate (gamma_n = n u / (1 - n u) per dot "
              "product of n terms, LayerNorm, GELU) times |d logit / d intermediate| (docs/fixed_point.md, "
              "'The float path: tolerance')")
LEGACY_TOLERANCE = 1e-5  # what a bundle written before the bound records (manifest onnx.tolerance)


def gamma(n: int) -> float:
    nu = n * U
    return nu / (1.0 - nu)


def _f64(t: torch.Tensor) -> torch.Tensor:
    """A float64 copy of a float32 parameter (its exact value)."""
    return t.detach().cpu().to(torch.float32).to(torch.float64)


def float_bound(model: torch.nn.Module, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(logits, E), both (N, 3): the exact logits (float64 evaluation of the float32 network) and the first-order
    forward error bound E of one float32 evaluation, for float32 `inputs` (N, 12) in physical units."""
    a = torch.from_numpy(np.asarray(inputs, dtype=np.float32).astype(np.float64))
    eps = float(np.float32(model.norms[0].eps))
    nodes: list[tuple[torch.Tensor, torch.Tensor]] = []  # (intermediate, bound of the rounding computing it adds)

    def node(t: torch.Tensor, rho: torch.Tensor) -> torch.Tensor:
        if not t.requires_grad:
            t.requires_grad_()
        t.retain_grad()
        nodes.append((t, rho.detach()))
        return t

    def linear(x: torch.Tensor, w: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        xd = x.detach()
        return node(x @ w.T + b, gamma(w.shape[1] + 1) * (xd.abs() @ w.abs().T + b.abs()))

    with torch.enable_grad():
        x = a
        for lin, norm in zip(model.linears, model.norms):
            w, b, g, beta = _f64(lin.weight), _f64(lin.bias), _f64(norm.weight), _f64(norm.bias)
            width = w.shape[0]
            h = linear(x, w, b)
            hd = h.detach().abs()
            rho_mu = gamma(width + 1) * hd.mean(dim=1, keepdim=True)
            mu = node(h.mean(dim=1, keepdim=True), rho_mu)
            d = h - mu
            v = (d * d).mean(dim=1, keepdim=True)
            m2 = (hd * hd).mean(dim=1, keepdim=True)
            v = node(v, 2 * gamma(width + 3) * torch.sqrt(m2 * v.detach()) + rho_mu ** 2)
            r = (v + eps).rsqrt()
            r = node(r, 5 * U * r.detach())
            z = d * r
            z = node(z, 3 * U * (hd + mu.detach().abs()) * r.detach() + U * z.detach().abs())
            y = g * z + beta
            y = node(y, gamma(2) * ((g * z).detach().abs() + beta.abs()))
            x = node(F.gelu(y), GELU_REL * y.detach().abs())
        logits = linear(x, _f64(model.head.weight), _f64(model.head.bias))
        e = torch.zeros_like(logits.detach())
        for c in range(logits.shape[1]):
            for t, _ in nodes:
                t.grad = None
            # rows are independent, so the gradient of the column's sum is every row's own gradient; the head's own
            # rounding enters through the logits node (gradient 1 for class c, 0 for the others)
            logits[:, c].sum().backward(retain_graph=c + 1 < logits.shape[1])
            for t, rho in nodes:
                e[:, c] += (t.grad.abs() * rho).sum(dim=1)
    return logits.detach().numpy(), e.numpy()


def round_up(x: float, digits: int = 3) -> float:
    """x rounded up to `digits` significant digits (at most 10^(1 - digits) above it): a bound stays a bound, and
    the manifest's bytes do not depend on the last bits of a float64 sum (tests/test_determinism.py)."""
    if not x > 0.0:
        return 0.0
    e = math.floor(math.log10(x)) - (digits - 1)
    return float(f"{math.ceil(x / 10.0 ** e)}e{e}")


def float_tolerance(model: torch.nn.Module, inputs: np.ndarray) -> dict:
    """The manifest's `float_tolerance` entry for `model` on `inputs` (the bundle's test vectors); the tolerance is
    the bound rounded up to 3 significant digits."""
    logits, e = float_bound(model, inputs)
    scaled = 2.0 * e / np.maximum(1.0, np.abs(logits))
    return {
        "tolerance": round_up(float(scaled.max())),
        "rule": RULE,
        "derivation": DERIVATION,
        "max_abs_bound": float(f"{2.0 * e.max():.3g}"),
        "median_abs_bound": float(f"{np.median(2.0 * e):.3g}"),
        "worst_vector": int(np.unravel_index(int(np.argmax(scaled)), scaled.shape)[0]),
        "unit_roundoff": U,
        "gelu_rel_error": GELU_REL,
    }


def recorded_tolerance(manifest: dict) -> float:
    """The float tolerance a bundle records: `float_tolerance.tolerance`, or for a bundle written before the bound
    existed its `onnx.tolerance` (1e-5)."""
    entry = manifest.get("float_tolerance")
    if isinstance(entry, dict) and "tolerance" in entry:
        return float(entry["tolerance"])
    return float(manifest.get("onnx", {}).get("tolerance", LEGACY_TOLERANCE))


def excess(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a - ref| / max(1, |ref|): the smallest tolerance under which the rule accepts `a` against `ref`."""
    a, ref = np.asarray(a, np.float64), np.asarray(ref, np.float64)
    return float((np.abs(a - ref) / np.maximum(1.0, np.abs(ref))).max(initial=0.0))
