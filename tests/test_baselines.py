"""Baselines of the paper's table: each runs under the step budget, returns a model of the
right size, and beats chance on an easy synthetic problem; the DARE/TIES operations are
checked on small hand-made vectors."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from fleetlab.evaluation.metrics import classification_metrics
from fleetlab.fusion import baselines as bl
from fleetlab.fusion.baselines.adamerging import merge_with_coefficients, tensor_index
from fleetlab.fusion.baselines.common import cal_objective, layer_slices, tensor_slices
from fleetlab.fusion.baselines.evomerge import expand_layerwise
from fleetlab.fusion.buffer import make_buffer
from fleetlab.fusion.rebasin import align_to_reference
from fleetlab.models import batched_logits, build, flatten, n_params
from fleetlab.models.train import train_classifier

ARCH = "sn-s"
STEPS = 40  # a reduced budget keeps the file fast; the default is BUDGET_STEPS = 130


def blobs(n: int, shift: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Three well-separated Gaussian classes in 12-D, the whole cloud shifted per 'domain'."""
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 3, n)
    centres = np.eye(3, 12) * 3.0
    return (centres[y] + rng.normal(size=(n, 12)) + shift).astype(np.float32), y


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """Tiny models: one intra-op thread is faster than two fighting over a loaded CPU."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def problem():
    torch.manual_seed(0)
    init = build(ARCH, seed=0)
    experts = [
        train_classifier(copy.deepcopy(init), *blobs(400, shift, seed), epochs=4, seed=seed)
        for seed, shift in enumerate((0.0, 0.4, -0.4))
    ]
    aligned = torch.stack(align_to_reference(experts, ARCH))
    x_cal, y_cal = blobs(150, 0.2, 10)
    x_test, y_test = blobs(600, 0.2, 11)
    return dict(experts=experts, flats=torch.stack([flatten(m) for m in experts]), aligned=aligned,
                x_cal=x_cal, y_cal=y_cal, x_test=x_test, y_test=y_test)


def balanced_accuracy(flat: torch.Tensor, x: np.ndarray, y: np.ndarray) -> float:
    pred = batched_logits(ARCH, flat.unsqueeze(0), torch.as_tensor(x))[0].argmax(1).numpy()
    return classification_metrics(y, pred)["balanced_accuracy"]


BASELINES = {
    "model-base": lambda p: flatten(bl.model_base(ARCH, p["x_cal"], p["y_cal"], seed=1, steps=STEPS)),
    "earth-ft": lambda p: flatten(bl.earth_finetune(p["experts"][0], p["x_cal"], p["y_cal"], seed=1, steps=STEPS)),
    "joint-ft": lambda p: flatten(bl.joint_finetune(p["experts"][1], p["x_cal"], p["y_cal"], seed=1, steps=STEPS)),
    "adamerging": lambda p: bl.adamerging(p["aligned"], ARCH, p["x_cal"], p["y_cal"], seed=1, steps=STEPS),
    "evomerge": lambda p: bl.evomerge(p["aligned"], ARCH, p["x_cal"], p["y_cal"], seed=1, steps=STEPS),
    "modelswarm": lambda p: bl.modelswarm(p["aligned"], ARCH, p["x_cal"], p["y_cal"], seed=1, steps=STEPS),
    "distill": lambda p: flatten(bl.distill(p["flats"], ARCH, p["x_cal"], p["y_cal"], seed=1, steps=STEPS)),
}


@pytest.mark.parametrize("name", list(BASELINES))
def test_baseline_returns_a_model_better_than_chance(problem, name):
    flat = BASELINES[name](problem)
    assert flat.shape == (n_params(ARCH),)
    assert torch.isfinite(flat).all()
    # Chance is 1/3; the classes are three standard deviations apart.
    assert balanced_accuracy(flat, problem["x_test"], problem["y_test"]) > 0.8


def test_modelswarm_improves_on_weak_experts(problem):
    """The experts of `problem` already score above 0.8, so returning one of them would pass the test above.
    From weak experts (one epoch on 60 rows each: about chance for two of them) the swarm must find a model
    better than the best of them, on D_Cal and on held-out rows."""
    weak = [train_classifier(copy.deepcopy(build(ARCH, seed=s)), *blobs(60, shift, s), epochs=1, seed=s)
            for s, shift in enumerate((0.0, 0.4, -0.4))]
    aligned = torch.stack(align_to_reference(weak, ARCH))
    loss = cal_objective(ARCH, problem["x_cal"], problem["y_cal"])
    swarm = bl.modelswarm(aligned, ARCH, problem["x_cal"], problem["y_cal"], seed=1, steps=STEPS)
    best_expert = max(balanced_accuracy(a, problem["x_test"], problem["y_test"]) for a in aligned)
    assert best_expert < 0.75  # the starting point leaves room to improve
    assert float(loss(swarm.unsqueeze(0))[0]) < 0.95 * float(loss(aligned).min())
    assert balanced_accuracy(swarm, problem["x_test"], problem["y_test"]) > best_expert + 0.03


@pytest.mark.parametrize("name", ["evomerge", "modelswarm", "distill", "model-base"])
def test_baseline_is_deterministic_for_a_seed(problem, name):
    assert torch.equal(BASELINES[name](problem), BASELINES[name](problem))


def test_inputs_are_left_untouched(problem):
    before_model = flatten(problem["experts"][0]).clone()
    before_aligned = problem["aligned"].clone()
    BASELINES["earth-ft"](problem)
    BASELINES["adamerging"](problem)
    BASELINES["evomerge"](problem)
    assert torch.equal(flatten(problem["experts"][0]), before_model)
    assert torch.equal(problem["aligned"], before_aligned)


def test_searches_improve_the_calibration_loss(problem):
    """The gradient-free searches return the best model they evaluated: never worse on D_Cal
    than their starting points."""
    loss = cal_objective(ARCH, problem["x_cal"], problem["y_cal"])
    buffer = make_buffer(problem["aligned"], copies=15, sigma=0.05, seed=3, kind="experts")
    best, history = bl.pso(buffer, ARCH, problem["x_cal"], problem["y_cal"], seed=3, steps=STEPS)
    assert len(history) == STEPS
    assert all(b <= a + 1e-7 for a, b in zip(history, history[1:]))  # best-so-far never rises
    assert float(loss(best.unsqueeze(0))[0]) <= float(loss(buffer).min()) + 1e-6
    merged = bl.evomerge(problem["aligned"], ARCH, problem["x_cal"], problem["y_cal"], seed=3, steps=STEPS)
    assert float(loss(merged.unsqueeze(0))[0]) < float(loss(problem["aligned"][:1])[0])
    start = bl.adamerging(problem["aligned"], ARCH, problem["x_cal"], problem["y_cal"], steps=0)
    learned = bl.adamerging(problem["aligned"], ARCH, problem["x_cal"], problem["y_cal"], steps=STEPS)
    assert float(loss(learned.unsqueeze(0))[0]) < float(loss(start.unsqueeze(0))[0])


def test_sn_d_baselines_have_the_sn_d_size(problem):
    x, y = problem["x_cal"], problem["y_cal"]
    init = build("sn-d", seed=0)
    experts = [train_classifier(copy.deepcopy(init), x, y, steps=5, seed=s) for s in range(3)]
    aligned = torch.stack(align_to_reference(experts, "sn-d"))
    assert bl.adamerging(aligned, "sn-d", x, y, steps=2).shape == (12547,)
    assert bl.evomerge(aligned, "sn-d", x, y, steps=2).shape == (12547,)
    assert len(layer_slices("sn-d")) == 4 and layer_slices("sn-d")[-1].stop == 12547


# --- the merging operations, by hand --------------------------------------------------------

def test_dare_drops_and_rescales():
    tau = torch.tensor([[1.0, -2.0, 3.0, 4.0]])
    u = torch.tensor([[0.1, 0.7, 0.4, 0.9]])
    out = bl.dare(tau, torch.tensor(0.5), u)
    assert torch.equal(out, torch.tensor([[2.0, 0.0, 6.0, 0.0]]))  # kept where u < 0.5, doubled
    assert torch.equal(bl.dare(tau, torch.tensor(1.0), u), tau)  # density 1: unchanged
    # In expectation DARE leaves the task vector unchanged.
    many = bl.dare(torch.ones(1, 200_000), torch.tensor(0.3), torch.rand(1, 200_000, generator=torch.Generator().manual_seed(0)))
    assert many.mean().item() == pytest.approx(1.0, abs=0.02)


def test_ties_trim_elect_and_disjoint_merge():
    tau = torch.tensor([[0.5, -3.0, 0.1, 2.0], [-1.0, -1.0, 0.2, -4.0]])
    trimmed = bl.ties_trim(tau, 0.5)  # keep the 2 largest magnitudes of each row
    assert torch.equal(trimmed, torch.tensor([[0.0, -3.0, 0.0, 2.0], [-1.0, -1.0, 0.0, -4.0]]))
    sign = bl.elect_sign(trimmed)  # column sums: -1, -4, 0, -2
    assert torch.equal(sign, torch.tensor([-1.0, -1.0, 1.0, -1.0]))
    merged = bl.disjoint_merge(trimmed, sign)
    # column 0: only -1 agrees; column 1: mean(-3, -1); column 2: nothing; column 3: only -4
    assert torch.equal(merged, torch.tensor([-1.0, -2.0, 0.0, -4.0]))
    base = torch.tensor([1.0, 1.0, 1.0, 1.0])
    assert torch.equal(bl.ties_merge(base, tau, density=0.5, scale=0.5), base + 0.5 * merged)


def test_dare_ties_merge_batched_candidates():
    base = torch.zeros(3)
    tau = torch.tensor([[1.0, 2.0, -1.0], [3.0, -2.0, -3.0]])
    u = torch.zeros(2, 3)  # nothing dropped at any density > 0
    weight = torch.stack([torch.ones(2, 3), 0.5 * torch.ones(2, 3)])  # two candidates
    out = bl.dare_ties_merge(base, tau, weight, torch.ones(2, 2, 3), u)
    assert out.shape == (2, 3)
    # candidate 0: column 1 has +2 vs -2 -> sum 0 -> sign +, only +2 kept
    assert torch.allclose(out[0], torch.tensor([2.0, 2.0, -2.0]))
    assert torch.allclose(out[1], 0.5 * out[0])


def test_adamerging_coefficients_and_base():
    aligned = torch.tensor([[1.0, 1.0, 1.0], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
    base, tau = bl.merge_base(aligned)
    assert torch.equal(base, aligned[0]) and torch.equal(tau, aligned[1:] - aligned[0])
    index = torch.tensor([0, 0, 1])
    coef = torch.tensor([[0.5, 1.0], [0.25, 0.0]])
    merged = merge_with_coefficients(base, tau, coef, index)
    assert torch.allclose(merged, torch.tensor([1.0 + 0.5 - 0.25, 1.0 + 1.0 + 0.0, 1.0 + 0.0 + 0.0]))
    idx = tensor_index(ARCH)
    assert idx.numel() == 543 and int(idx.max()) == 5
    assert [s.stop - s.start for s in tensor_slices(ARCH)] == [360, 30, 30, 30, 90, 3]
    assert expand_layerwise(torch.tensor([[1.0, 2.0]]), ARCH).shape == (1, 543)


def test_adamerging_without_steps_is_task_arithmetic(problem):
    out = bl.adamerging(problem["aligned"], ARCH, problem["x_cal"], problem["y_cal"], steps=0, init=0.3)
    base, tau = bl.merge_base(problem["aligned"])
    assert torch.allclose(out, base + 0.3 * tau.sum(0))


def test_bad_input_is_refused(problem):
    with pytest.raises(ValueError, match="at least two"):
        bl.adamerging(problem["aligned"][:1], ARCH, problem["x_cal"], problem["y_cal"])
    with pytest.raises(ValueError, match="empty"):
        bl.distill(problem["flats"], ARCH, problem["x_cal"][:0], problem["y_cal"][:0])
    with pytest.raises(ValueError, match="alpha"):
        bl.distill(problem["flats"], ARCH, problem["x_cal"], problem["y_cal"], alpha=1.5)
    with pytest.raises(ValueError, match="buffer"):
        bl.pso(problem["aligned"][0], ARCH, problem["x_cal"], problem["y_cal"])
