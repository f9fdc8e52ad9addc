"""Git Re-Basin weight matching: permutations keep the function and bring weights closer."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fleetlab.fusion.rebasin import align_to_reference, match_permutations, permute_flat
from fleetlab.models import batched_logits, build, flatten, load_flat
from fleetlab.models.mlp import hidden_sizes


def _inputs(n=64, seed=0):
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(n, 12, generator=gen) * 2.0


def _random_model(arch: str, seed: int) -> torch.Tensor:
    """A model with non-trivial LayerNorm affine parameters (defaults are all 1 / 0)."""
    gen = torch.Generator().manual_seed(seed + 100)
    flat = flatten(build(arch, seed=seed))
    return flat + 0.2 * torch.randn(flat.shape, generator=gen)


def _random_perms(arch: str, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.permutation(h) for h in hidden_sizes(arch)]


@pytest.mark.parametrize("arch", ["sn-s", "sn-d", "24,9", "16,12,8,6"])
def test_permuted_model_computes_the_same_function(arch):
    flat = _random_model(arch, 0)
    permuted = permute_flat(arch, flat, _random_perms(arch, 1))
    assert not torch.allclose(permuted, flat)
    x = _inputs()
    model_a, model_b = load_flat(build(arch), flat).eval(), load_flat(build(arch), permuted).eval()
    with torch.no_grad():
        # float32 sums in another order: a few ULPs, more through four LayerNorms
        torch.testing.assert_close(model_b(x), model_a(x), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(batched_logits(arch, permuted, x), batched_logits(arch, flat, x), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("arch", ["sn-s", "sn-d", "24,9", "16,12,8,6"])
def test_alignment_undoes_a_permutation_exactly(arch):
    ref = _random_model(arch, 3)
    shuffled = permute_flat(arch, ref, _random_perms(arch, 4))
    aligned = align_to_reference([load_flat(build(arch), ref), load_flat(build(arch), shuffled)], arch)
    torch.testing.assert_close(aligned[0], ref)
    torch.testing.assert_close(aligned[1], ref)


@pytest.mark.parametrize("arch", ["sn-s", "sn-d"])
def test_alignment_keeps_functions_and_moves_weights_closer(arch):
    flats = [_random_model(arch, s) for s in (10, 11, 12)]
    models = [load_flat(build(arch), f).eval() for f in flats]
    aligned = align_to_reference(models, arch, reference=0)
    x = _inputs(seed=5)
    torch.testing.assert_close(aligned[0], flats[0])  # the reference is not moved
    for before, after in zip(flats[1:], aligned[1:]):
        torch.testing.assert_close(batched_logits(arch, after, x), batched_logits(arch, before, x), rtol=1e-5, atol=1e-5)
        d_before = float((before - flats[0]).norm())
        d_after = float((after - flats[0]).norm())
        assert d_after < 0.97 * d_before  # independent random models: matching gains clearly


@pytest.mark.parametrize("arch", ["sn-d", "24,9", "16,12,8,6"])
def test_rebasin_permutes_every_hidden_layer(arch):
    """A model shuffled in every hidden layer at once: matching finds each layer's permutation
    (the inverse of the shuffle), not only the first or the last one."""
    ref = _random_model(arch, 30)
    shuffle = _random_perms(arch, 31)
    assert all(not np.array_equal(p, np.arange(len(p))) for p in shuffle)
    shuffled = permute_flat(arch, ref, shuffle)
    perms = match_permutations(arch, ref, shuffled)
    assert len(perms) == len(hidden_sizes(arch))
    for layer, (found, applied) in enumerate(zip(perms, shuffle)):
        # new unit i of `shuffled` is old unit applied[i]; matching must map ref unit j to applied^-1[j]
        np.testing.assert_array_equal(found, np.argsort(applied), err_msg=f"hidden layer {layer}")


def test_permutations_are_valid_and_a_different_reference_works():
    arch = "sn-d"
    flats = [_random_model(arch, s) for s in (20, 21)]
    perms = match_permutations(arch, flats[0], flats[1])
    for p, h in zip(perms, hidden_sizes(arch)):
        assert sorted(p.tolist()) == list(range(h))
    models = [load_flat(build(arch), f) for f in flats]
    aligned = align_to_reference(models, arch, reference=1)
    torch.testing.assert_close(aligned[1], flats[1])


def test_bad_input():
    with pytest.raises(ValueError, match="no models"):
        align_to_reference([], "sn-s")
    with pytest.raises(ValueError, match="out of range"):
        align_to_reference([build("sn-s", seed=0)], "sn-s", reference=3)
    with pytest.raises(ValueError, match="permutations"):
        permute_flat("sn-s", flatten(build("sn-s", seed=0)), [np.arange(5)])
