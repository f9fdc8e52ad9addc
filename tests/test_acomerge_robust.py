"""`acomerge-robust` (issue 17): registered, fits on a small synthetic problem, returns one SN-S that
`fleetlab export --check` turns into a bundle, and its one mechanism — AcoMerge over experts
fine-tuned on D_Cal first — is checked against what it must change."""

from __future__ import annotations

import contextlib
import copy
import io

import numpy as np
import pytest
import torch

from fleetlab.cli import main
from fleetlab.evaluation.methods import parse_methods
from fleetlab.fusion import registry
from fleetlab.fusion.fitness import CalibrationFitness
from fleetlab.fusion.rebasin import align_to_reference
from fleetlab.fusion.registry import Budget, FusionInputs
from fleetlab.fusion.robust import NAME, finetuned_experts
from fleetlab.models import batched_logits, build, flatten, n_params, save_model
from fleetlab.models.train import train_classifier

ARCH = "sn-s"
# A reduced budget keeps the file fast (the default is 130 steps, 300 ants).
BUDGET = Budget(steps=20, ants=40)


def blobs(n: int, shift: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Three separable Gaussian classes in 12-D; `shift` moves the whole cloud (one 'rover' each)."""
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 3, n)
    return (np.eye(3, 12)[y] * 3.0 + rng.normal(size=(n, 12)) + shift).astype(np.float32), y


@pytest.fixture(scope="module")
def inputs():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny models: one thread is faster on a loaded CPU
    init = build(ARCH, seed=0)
    experts = [train_classifier(copy.deepcopy(init), *blobs(300, shift, seed), epochs=3, seed=seed)
               for seed, shift in enumerate((0.0, 0.8, -0.8))]
    flats = torch.stack([flatten(m) for m in experts])
    x_cal, y_cal = blobs(150, 1.5, 10)  # the target domain sits away from every expert's
    yield FusionInputs(arch=ARCH, roles=("earth", "fleet_a", "fleet_b"), experts=flats,
                       aligned=torch.stack(align_to_reference(experts, ARCH)), joint=None,
                       x_cal=x_cal, y_cal=y_cal, seed=3, buffer_seed=4, budget=BUDGET)
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def fused(inputs):
    return registry.fit(NAME, inputs)


def test_registered_and_selectable():
    assert NAME in registry.selectable()
    assert registry.get(NAME).group == "Merging"  # ranked in the table like the other merges
    assert NAME in parse_methods(f"earth-ft,{NAME}")
    assert "acomerge" in registry.selectable()  # the paper's AcoMerge stays beside it


def test_returns_one_sn_s_that_beats_chance(inputs, fused):
    assert fused.method == NAME and fused.arch == ARCH
    assert fused.flat.shape == (n_params(ARCH),) and torch.isfinite(fused.flat).all()
    x_test, y_test = blobs(600, 1.5, 11)
    pred = batched_logits(ARCH, fused.flat.unsqueeze(0), torch.as_tensor(x_test))[0].argmax(1).numpy()
    assert (pred == y_test).mean() > 0.6  # chance is 1/3
    assert len(fused.curve) == BUDGET.steps  # one best-so-far entry per generation


def test_search_starts_from_the_finetuned_experts(inputs, fused):
    """The mechanism: the experts in AcoMerge's buffer are the D_Cal-fine-tuned ones, which fit the
    shifted target better than the raw experts, and the search returns nothing worse than them."""
    fitness = CalibrationFitness(ARCH, inputs.x_cal, inputs.y_cal)
    raw = fitness(inputs.aligned)
    tuned = finetuned_experts(inputs)
    j_tuned = fitness(tuned)
    assert torch.all(j_tuned < raw), (raw, j_tuned)
    # what the search saw as its experts is exactly the fine-tuned set (same seeds, same values)
    assert np.allclose(fused.details["finetuned_expert_fitness"], j_tuned.numpy(), rtol=1e-5)
    assert fused.details["best_fitness"] <= float(j_tuned.min()) + 1e-6
    assert float(fitness(fused.flat)) == pytest.approx(fused.details["best_fitness"], rel=1e-4)
    # and the paper's AcoMerge, on the raw experts, reports the raw experts' fitness instead
    paper = registry.fit("acomerge", inputs)
    assert np.allclose(paper.details["expert_fitness"], raw.numpy(), rtol=1e-5)


def test_the_fused_model_exports_to_a_checked_bundle(fused, tmp_path):
    path = save_model(tmp_path / "fused.pt", fused.module(), {"method": NAME})
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["export", str(path), "--out", str(tmp_path / "bundle"), "--check"])
    assert code == 0, err.getvalue()
    assert "integer reference reproduces q_logits bit for bit" in out.getvalue()
