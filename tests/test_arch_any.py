"""Architectures as data (issue 28, item 1): --arch takes sn-s, sn-d or hidden sizes such as 64,32,
and every registered fusion method, saving/loading and the batched forward accept any of them."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from fleetlab.fusion import registry
from fleetlab.fusion.rebasin import align_to_reference
from fleetlab.fusion.registry import Budget, FusionInputs
from fleetlab.models import batched_logits, build, canonical_arch, flatten, hidden_sizes, load_model, n_params, save_model
from fleetlab.models.train import train_classifier

IRREGULAR = "24,9"


def test_arch_names_and_sizes():
    assert hidden_sizes("sn-s") == (30,) and hidden_sizes("sn-d") == (128, 64, 32)
    assert hidden_sizes("64,32") == (64, 32) and hidden_sizes(" 2, 256,3,4") == (2, 256, 3, 4)
    assert canonical_arch("30") == "sn-s" and canonical_arch("128,64,32") == "sn-d"
    assert canonical_arch("24, 9") == "24,9"
    # 12*24+24 + 2*24 + 24*9+9 + 2*9 + 9*3+3 parameters
    assert n_params(IRREGULAR) == 12 * 24 + 24 + 48 + 24 * 9 + 9 + 18 + 9 * 3 + 3


@pytest.mark.parametrize("bad", ["sn-x", "", "64,,32", "1", "257", "8,8,8,8,8", "0,4", "a,b"])
def test_bad_arch_is_refused_with_the_accepted_forms(bad):
    with pytest.raises(ValueError, match="architecture"):
        hidden_sizes(bad)


def test_cli_arch_option_refuses_in_one_line(capsys):
    from fleetlab.cli import main

    with pytest.raises(SystemExit):
        main(["fuse", "--data", "x", "--out", "y", "--arch", "300"])
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("1 to 4 hidden layers of 2 to 256 units are supported")


def test_save_load_keeps_an_irregular_arch(tmp_path):
    m = build(IRREGULAR, seed=3)
    back, meta = load_model(save_model(tmp_path / "m.pt", m))
    assert meta["arch"] == IRREGULAR and back.hidden == (24, 9)
    assert torch.equal(flatten(back), flatten(m))
    x = torch.randn(20, 12)
    torch.testing.assert_close(batched_logits(IRREGULAR, flatten(m), x)[0], back(x), atol=2e-5, rtol=1e-5)


def _blobs(n: int, shift: float, seed: int):
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 3, n)
    return (np.eye(3, 12)[y] * 3.0 + rng.normal(size=(n, 12)) + shift).astype(np.float32), y


@pytest.mark.parametrize("arch", [IRREGULAR, "16,12,8,6"])
def test_every_registered_method_fuses_any_arch(arch):
    """Each method of the registry (ablations included) returns a finite model of the right size."""
    torch.set_num_threads(1)
    init = build(arch, seed=0)
    experts = [train_classifier(copy.deepcopy(init), *_blobs(200, s, i), steps=5, seed=i)
               for i, s in enumerate((0.0, 0.4, -0.4))]
    x_cal, y_cal = _blobs(60, 0.2, 10)
    flats = torch.stack([flatten(m) for m in experts])
    inputs = FusionInputs(arch=arch, roles=("earth", "a", "b"), experts=flats,
                          aligned=torch.stack(align_to_reference(experts, arch)), joint=flats[0].clone(),
                          x_cal=x_cal, y_cal=y_cal, seed=1, buffer_seed=2,
                          budget=Budget(steps=2, ants=4, copies=1),
                          # unsure labels, for the methods that fit on them (acomerge-vo: the deep nets' path)
                          y_cal_probs=0.7 * np.eye(3)[y_cal] + 0.3 * np.eye(3)[(y_cal + 1) % 3])
    methods = registry.all_methods()
    assert len(methods) >= 10
    for name in methods:
        fused = registry.fit(name, inputs)
        assert fused.arch == arch, name
        assert fused.flat.shape == (n_params(arch),), name
        assert torch.isfinite(fused.flat).all(), name
        assert fused.module().hidden == hidden_sizes(arch), name
