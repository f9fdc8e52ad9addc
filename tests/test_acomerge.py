"""AcoMerge: search behaviour on known optima, MMAS invariants, IWOA moves, batched fitness."""

from __future__ import annotations

import dataclasses
import math
import threading

import numpy as np
import pytest
import torch
from torch.nn import functional as F

from fleetlab.fusion.acomerge import (
    AcoMergeConfig,
    Ants,
    acomerge,
    construct_ants,
    construct_departures,
    evaluate_ants,
    mmas_bounds,
    search,
    whale_update,
)
from fleetlab.fusion.bench import synthetic_calibration
from fleetlab.fusion.buffer import make_buffer
from fleetlab.fusion.finetune import finetune
from fleetlab.fusion import fitness as fitness_module
from fleetlab.fusion.fitness import CalibrationFitness, fitness_seconds
from fleetlab.models import build, flatten, load_flat, n_params
from fleetlab.models.train import class_weights

SMALL = AcoMergeConfig(n_ants=60, generations=24, iwoa_every=6)


@pytest.fixture(scope="module")
def cal():
    return synthetic_calibration(120, seed=3)


@pytest.fixture(scope="module")
def experts(cal):
    x, y = cal
    return torch.stack([flatten(finetune(build("sn-s", seed=k), x, y, steps=25, seed=k)) for k in range(3)])


def module_ce(arch: str, flat: torch.Tensor, x: np.ndarray, y: np.ndarray) -> float:
    """Weighted CE of one model through the ordinary nn.Module in eval mode."""
    model = load_flat(build(arch), flat).eval()
    with torch.no_grad():
        logits = model(torch.from_numpy(x))
    return float(F.cross_entropy(logits, torch.from_numpy(y), weight=class_weights(y)))


# --- batched fitness ------------------------------------------------------------------

@pytest.mark.parametrize("arch", ["sn-s", "sn-d"])
def test_batched_fitness_equals_module_loss(arch, cal):
    x, y = cal
    gen = torch.Generator().manual_seed(0)
    flats = torch.stack([flatten(build(arch, seed=s)) for s in range(5)])
    flats = flats + 0.3 * torch.randn(flats.shape, generator=gen)  # non-trivial LayerNorm affine too
    batched = CalibrationFitness(arch, x, y, chunk=2)(flats)
    expected = torch.tensor([module_ce(arch, f, x, y) for f in flats])
    torch.testing.assert_close(batched, expected, rtol=1e-5, atol=1e-5)


def test_fitness_buffer_reuse_keeps_every_call_independent(cal):
    """The SN-S path writes its first layer's operands and activations into buffers kept across calls
    (fitness._operands): calls of different sizes in any order, the last chunk shorter, give the same bits
    as a fresh object per call, and as new NaN-filled buffers per chunk (every value is written before
    it is read)."""
    x, y = cal
    gen = torch.Generator().manual_seed(1)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)]).repeat(70, 1)[:203]
    flats = flats + 0.3 * torch.randn(flats.shape, generator=gen)
    kept = CalibrationFitness("sn-s", x, y, chunk=150)
    for part in (flats, flats[:7], flats[50:], flats[:2], flats):  # 150 + 53, 7, 150 + 3, 2, 150 + 53
        assert torch.equal(kept(part), CalibrationFitness("sn-s", x, y, chunk=150)(part))
    fresh = CalibrationFitness("sn-s", x, y, chunk=150)
    unkept = fresh._operands

    def nan_filled(p: int, h: int, size: int):  # new buffers every call, NaN wherever the fitness would not write
        fresh._kept = None
        a, b, act, logits = unkept(p, h, size)
        for buf in (a, b[:, :-1], act, logits):
            buf.fill_(float("nan"))
        return a, b, act, logits

    fresh._operands = nan_filled
    assert torch.equal(kept(flats), fresh(flats))


class _TickClock:
    """A clock that moves one second each time it is read: a call timed once adds exactly 1."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 1.0
        return self.now


def test_fitness_time_counts_each_call_once_on_its_own_thread(cal, monkeypatch):
    """`fitness_seconds` (what evaluate and bench fusion report as the fitness's share): a lone model,
    evaluated inside as a batch of two, is one call and counted once, and a call on another thread
    is that thread's, not this one's. Simulated clocks: each call adds exactly one tick to each sum."""
    monkeypatch.setattr(fitness_module.time, "perf_counter", _TickClock())
    monkeypatch.setattr(fitness_module.time, "process_time", _TickClock())
    x, y = cal
    fit = CalibrationFitness("sn-s", x, y)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(40)])
    before = fitness_seconds()
    for _ in range(5):
        fit(flats[0])
        fit(flats)
    assert tuple(a - b for a, b in zip(fitness_seconds(), before)) == (10.0, 10.0)

    here = fitness_seconds()
    other = threading.Thread(target=lambda: [fit(flats) for _ in range(5)])
    other.start()
    other.join()
    assert fitness_seconds() == here


def test_fitness_rejects_bad_calibration():
    with pytest.raises(ValueError, match="NaN"):
        CalibrationFitness("sn-s", np.full((4, 12), np.nan, dtype=np.float32), np.zeros(4, dtype=np.int64))
    with pytest.raises(ValueError, match="labels"):
        CalibrationFitness("sn-s", np.zeros((4, 12), dtype=np.float32), np.zeros(3, dtype=np.int64))
    with pytest.raises(ValueError, match="classes 0..2"):
        CalibrationFitness("sn-s", np.zeros((2, 12), dtype=np.float32), np.array([0, 3]))


# --- buffer -----------------------------------------------------------------------------

def test_expert_buffer_layout(experts):
    buf = make_buffer(experts, copies=15, sigma=0.05, seed=1)
    assert buf.shape == (48, n_params("sn-s"))
    torch.testing.assert_close(buf[:3], experts)  # rows 0..K-1 are the unperturbed experts
    noise = buf[3:].view(3, 15, -1) - experts.unsqueeze(1)  # copies are expert-major
    assert abs(float(noise.std()) - 0.05) < 0.002 and abs(float(noise.mean())) < 0.002
    assert torch.equal(buf, make_buffer(experts, 15, 0.05, seed=1))
    assert not torch.equal(buf, make_buffer(experts, 15, 0.05, seed=2))


def test_ablation_buffers(experts):
    cr = make_buffer(experts, 15, 0.05, seed=0, kind="centroid_random")
    rnd = make_buffer(experts, 15, 0.05, seed=0, kind="random")
    assert cr.shape == rnd.shape == (48, experts.shape[1])
    torch.testing.assert_close(cr[:3], experts)
    # centroid-random rows are centred on the experts' centroid, not on any expert
    assert float((cr[3:].mean(0) - experts.mean(0)).abs().mean()) < float((cr[3:].mean(0) - experts[0]).abs().mean())
    assert not any(torch.equal(r, e) for r in rnd for e in experts)
    with pytest.raises(ValueError, match="kind"):
        make_buffer(experts, 15, 0.05, 0, kind="nope")


# --- MMAS pieces ------------------------------------------------------------------------

def test_mmas_bounds_formula():
    tmin, tmax = mmas_bounds(best_j=0.5, deposit=1.0, n_choices=48, n_decisions=543, p_best=0.05)
    assert tmax == pytest.approx(2.0)
    p_dec = 0.05 ** (1 / 543)
    assert tmin == pytest.approx(2.0 * (1 - p_dec) / (47 * p_dec))
    assert 0 < tmin < tmax


def test_construct_greedy_and_roulette():
    gen = torch.Generator().manual_seed(0)
    tau = torch.tensor([[1.0, 3.0, 6.0], [5.0, 1.0, 4.0]])
    paths, explorer = construct_ants(tau, None, q0=1.0, n_ants=50, gen=gen)
    assert torch.equal(paths, torch.tensor([2, 0]).expand(50, 2)) and not explorer.any()
    paths, explorer = construct_ants(tau, None, q0=0.0, n_ants=40000, gen=gen)
    freq = torch.stack([torch.bincount(r, minlength=3) for r in paths.T]).float() / 40000
    torch.testing.assert_close(freq, tau / tau.sum(1, keepdim=True), atol=0.01, rtol=0)
    assert torch.equal(explorer, (paths != torch.tensor([2, 0])).any(dim=1))


def test_construct_follows_the_pseudo_random_proportional_rule():
    """P(j) = q0·[j = argmax τ] + (1 − q0)·τ_j/Στ for every index, here with a heuristic and α, β ≠ 1."""
    gen = torch.Generator().manual_seed(1)
    tau = torch.tensor([[1.0, 3.0, 6.0, 0.5], [5.0, 1.0, 4.0, 2.0], [0.2, 0.2, 0.2, 9.0]])
    eta = torch.tensor([[1.0, 2.0, 0.5, 1.0], [1.0, 1.0, 1.0, 3.0], [1.0, 1.0, 1.0, 1.0]])
    q0, alpha, beta, n = 0.6, 2.0, 0.5, 60000
    paths, _ = construct_ants(tau, eta, q0, n, gen, alpha, beta)
    w = tau**alpha * eta**beta
    expected = (1 - q0) * w / w.sum(1, keepdim=True)
    expected[torch.arange(3), tau.argmax(1)] += q0
    freq = torch.stack([torch.bincount(r, minlength=4) for r in paths.T]).float() / n
    torch.testing.assert_close(freq, expected, atol=0.008, rtol=0)


def _departures_row_by_row(tau, eta, q0, n_ants, gen, alpha, beta):
    """construct_ants' paths computed the plain way: every row's departures found with torch's
    nonzero and located by a search of that row alone (rows shifted by 2t, as the one flat search
    sees them), the same uniforms and float64 arithmetic."""
    n_idx, m = tau.shape
    rows = torch.arange(n_idx)
    greedy = tau.argmax(dim=1)
    weight = tau if alpha == 1.0 else tau.pow(alpha)
    weight = (weight if eta is None else weight * (eta if beta == 1.0 else eta.pow(beta))).to(torch.float64)
    w_greedy = weight[rows, greedy]
    w_others = weight.sum(dim=1) - w_greedy
    leave = ((1.0 - q0) * w_others / (w_others + w_greedy)).to(torch.float32)
    others = weight.clone()
    others[rows, greedy] = 0.0
    cdf = others.cumsum(dim=1) / w_others.unsqueeze(1)
    cdf[:, -1] = 1.0
    u = torch.rand(n_idx, n_ants, generator=gen)
    paths = greedy.to(torch.int32).expand(n_ants, n_idx).clone()
    for t in range(n_idx):
        ants = (u[t] < leave[t]).nonzero().squeeze(1)
        v = u[t, ants].to(torch.float64) / leave[t]
        paths[ants, t] = torch.searchsorted(cdf[t] + 2.0 * t, 2.0 * t + v, right=True).clamp(max=m - 1).to(torch.int32)
    return paths


@pytest.mark.parametrize("case", ["spread", "heuristic", "alpha", "concentrated", "concentrated-heuristic"])
def test_construct_matches_the_row_by_row_rule(case):
    """Issue 30: the departures are found with numpy and indexed flat (faster); the paths are those
    of the plain row-by-row computation, bit for bit, early (spread pheromone) and late in a run
    (one candidate per index at τ_max, the rest at τ_min, few departures)."""
    gen = torch.Generator().manual_seed(11)
    n_idx, m = 543, 48
    tau = torch.rand(n_idx, m, generator=gen) + 0.5
    if case.startswith("concentrated"):
        tau = torch.full((n_idx, m), 1.2e-4)
        tau[torch.arange(n_idx), torch.randint(0, m, (n_idx,), generator=gen)] = 1.0
    eta = torch.rand(n_idx, m, generator=gen) + 0.1 if case.endswith("heuristic") else None
    alpha = 2.0 if case == "alpha" else 1.0
    for q0 in (0.0, 0.5, 0.95):
        paths, explorer = construct_ants(tau, eta, q0, 300, torch.Generator().manual_seed(5), alpha, 1.5)
        expected = _departures_row_by_row(tau, eta, q0, 300, torch.Generator().manual_seed(5), alpha, 1.5)
        assert torch.equal(paths, expected)
        assert torch.equal(explorer, (expected != tau.argmax(dim=1)).any(dim=1))
        assert explorer.any()


def test_greedy_ants_share_one_evaluation():
    """Ants that never left the greedy path get the greedy model's J; every other ant its own."""
    gen = torch.Generator().manual_seed(3)
    cand = torch.randn(6, 10, generator=gen)
    tau = torch.rand(10, 6, generator=gen) + 1.0
    paths, explorer = construct_ants(tau, None, 0.97, 40, gen)
    assert explorer.any() and not explorer.all()
    distinct_explorers = len({tuple(p.tolist()) for p in paths[explorer]})
    # one batch: the (distinct) explorers and one greedy representative
    assert _evaluation_sizes(paths, explorer, cand, tau.argmax(dim=1)) == [distinct_explorers + 1]


def _ants_of_paths(paths: torch.Tensor, greedy: torch.Tensor) -> Ants:
    """Dense paths (P, T) as departures from `greedy` (T,), in (index, ant) order."""
    p, g = paths.numpy().astype(np.int64), greedy.numpy().astype(np.int64)
    ant, t = np.nonzero(p != g)
    order = np.lexsort((ant, t))
    return Ants(g, t[order], ant[order], p[ant[order], t[order]], p.shape[0])


def _evaluation_sizes(paths: torch.Tensor, explorer: torch.Tensor, cand: torch.Tensor, greedy: torch.Tensor) -> list[int]:
    """evaluate_ants with a toy fitness: checks every ant's J, returns the sizes of the fitness calls."""
    calls = []

    def fitness(flats):
        calls.append(flats.shape[0])
        return flats.sum(dim=1) ** 2

    ants = _ants_of_paths(paths, greedy)
    assert np.array_equal(ants.explorer(), explorer.numpy()) and torch.equal(ants.dense(), paths.to(torch.int32))
    j = evaluate_ants(ants, cand, fitness)
    torch.testing.assert_close(j, cand.gather(0, paths).sum(dim=1) ** 2)
    return calls


def test_ants_with_the_same_path_share_one_evaluation():
    """Explorers that built the same model are evaluated once (issue 30) and each gets that model's J."""
    gen = torch.Generator().manual_seed(4)
    cand = torch.randn(6, 10, generator=gen)
    paths = torch.zeros(12, 10, dtype=torch.int32)
    paths[1:4, 2] = 3  # three explorers with one path
    paths[4:6, 7] = 5  # two with another
    paths[6, 2], paths[6, 7] = 3, 5  # one with both departures
    explorer = torch.zeros(12, dtype=torch.bool)
    explorer[1:7] = True
    greedy = torch.zeros(10, dtype=torch.long)
    assert _evaluation_sizes(paths, explorer, cand, greedy) == [4]  # three distinct explorer paths and the greedy one


def test_a_collision_of_keys_costs_only_the_sharing(monkeypatch):
    """Ants whose keys are equal but whose departures differ are each evaluated on their own, with
    their own J: here every cell has the same key, so all one-departure ants collide."""
    import fleetlab.fusion.acomerge as aco

    gen = torch.Generator().manual_seed(4)
    cand = torch.randn(6, 10, generator=gen)
    paths = torch.zeros(5, 10, dtype=torch.int32)
    paths[1, 2], paths[2, 7], paths[3, 2] = 3, 5, 3  # ants 1 and 3 build one model, ant 2 another
    explorer = torch.tensor([False, True, True, True, False])
    greedy = torch.zeros(10, dtype=torch.long)
    assert _evaluation_sizes(paths, explorer, cand, greedy) == [3]
    monkeypatch.setitem(aco._CELL_KEYS, 60, np.ones(60))
    assert _evaluation_sizes(paths, explorer, cand, greedy) == [4]


def test_an_ants_path_is_its_row_of_the_dense_paths():
    tau = torch.rand(30, 7, generator=torch.Generator().manual_seed(8)) + 0.5
    ants = construct_departures(tau, None, 0.6, 25, torch.Generator().manual_seed(9))
    dense = ants.dense()
    assert ants.t.size and np.all(np.diff(ants.t * 25 + ants.ant) > 0)  # (index, ant) order
    for a in range(25):
        assert torch.equal(ants.path(a), dense[a].long())
    assert np.array_equal(ants.explorer(), (dense != tau.argmax(dim=1)).any(dim=1).numpy())


def test_fitness_of_a_model_in_calls_of_other_sizes_agrees_to_rounding(cal):
    """Across calls of other sizes a model's J is equal to float rounding only: BLAS picks GEMM kernels by
    shape and CPU (on AMD Zen 2-4 and Intel Haswell a lone model's J differed in its last bit; issue 42).
    The rule in docs/architecture.md: the search's numbers are the same bits on one machine, not across
    batch shapes."""
    x, y = cal
    gen = torch.Generator().manual_seed(2)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)]).repeat(80, 1)[:230]
    flats = flats + 0.3 * torch.randn(flats.shape, generator=gen)
    fitness = CalibrationFitness("sn-s", x, y)
    whole = fitness(flats)
    for i in (0, 1, 57, 228):
        torch.testing.assert_close(fitness(flats[i]), whole[i : i + 1], rtol=1e-6, atol=0)
        torch.testing.assert_close(fitness(flats[i : i + 2]), whole[i : i + 2], rtol=1e-6, atol=0)
    torch.testing.assert_close(fitness(flats[100:203]), whole[100:203], rtol=1e-6, atol=0)


def test_ants_that_built_one_model_take_its_row_of_one_call(cal):
    """Sharing is exact by construction: every ant's J is, bit for bit, the row of its model in the one
    fitness call of its generation, and ants that built the same model get the same bits."""
    x, y = cal
    gen = torch.Generator().manual_seed(5)
    cand = torch.stack([flatten(build("sn-s", seed=s)) for s in range(6)])
    cand = cand + 0.1 * torch.randn(cand.shape, generator=gen)
    tau = torch.rand(cand.shape[1], 6, generator=gen) + 1.0
    ants = construct_departures(tau, None, 0.995, 60, gen)
    fitness = CalibrationFitness("sn-s", x, y)
    calls = []

    def spy(flats):
        calls.append((flats.clone(), fitness(flats)))
        return calls[-1][1]

    j = evaluate_ants(ants, cand, spy)
    assert len(calls) == 1
    rows, j_rows = calls[0]
    dense = ants.dense().long()
    models = cand.gather(0, dense)  # (P, T) every ant's model
    assert rows.shape[0] < dense.shape[0]  # some ants shared
    for a in range(dense.shape[0]):
        (match,) = torch.nonzero((rows == models[a]).all(dim=1), as_tuple=True)
        assert match.numel() == 1, a
        assert j[a].item() == j_rows[match[0]].item(), a


def test_fitness_does_not_depend_on_the_piece_size(cal, monkeypatch):
    """The SN-S activations are made in pieces of SUB_CHUNK ants per intra-op thread (`piece_size`): so
    that a run's numbers do not depend on the thread count through the pieces, J is the same bits in
    pieces of any size, a single ant's piece of a larger call excepted (it never occurs)."""
    x, y = cal
    gen = torch.Generator().manual_seed(3)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)]).repeat(60, 1)[:173]
    flats = flats + 0.3 * torch.randn(flats.shape, generator=gen)
    monkeypatch.setattr(fitness_module, "SUB_CHUNK", 25)
    kept = CalibrationFitness("sn-s", x, y)  # its buffers grow with the piece size (a thread count raised)
    reference = kept(flats)
    for size in (3, 7, 50, 86, 200, 25):
        monkeypatch.setattr(fitness_module, "SUB_CHUNK", size)
        assert fitness_module.piece_size() == size * torch.get_num_threads()
        assert torch.equal(CalibrationFitness("sn-s", x, y)(flats), reference), size
        assert torch.equal(kept(flats), reference), size


def _toy(n_idx=20, m=8, seed=0):
    """Separable objective with a known optimum: candidate `best[z]` of index z is the target."""
    gen = torch.Generator().manual_seed(seed)
    # well-separated candidates (a wrong pick costs at least 0.25), in random order per index
    cand = torch.stack([torch.randperm(m, generator=gen) for _ in range(n_idx)], dim=1) * 0.5
    best = torch.randint(0, m, (n_idx,), generator=gen)
    target = cand[best, torch.arange(n_idx)]

    def fitness(flats: torch.Tensor) -> torch.Tensor:
        return 1.0 + ((flats - target) ** 2).sum(dim=1)

    return cand.float(), target.float(), fitness


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mmas_finds_known_optimum(seed):
    cand, target, fitness = _toy(seed=seed)
    cfg = AcoMergeConfig(n_ants=100, generations=130, phases=("mmas",))
    res = search(cand[:3], cand, fitness, cfg, seed=seed)
    assert torch.equal(res.best_flat, target)
    assert res.best_fitness == pytest.approx(1.0)
    assert res.history["best_so_far"][-1] < res.history["best_so_far"][0]


def test_iwoa_reaches_an_optimum_between_the_candidates():
    cand, target, _ = _toy(seed=4)
    off_buffer = target + 0.2  # no candidate holds it: MMAS alone is stuck at 1 + 20 * 0.2^2

    def fitness(flats: torch.Tensor) -> torch.Tensor:
        return 1.0 + ((flats - off_buffer) ** 2).sum(dim=1)

    cfg = AcoMergeConfig(n_ants=100, generations=130)
    hybrid = search(cand[:3], cand, fitness, cfg, seed=0)
    mmas = search(cand[:3], cand, fitness, dataclasses.replace(cfg, phases=("mmas",)), seed=0)
    assert mmas.best_fitness == pytest.approx(1.8, abs=1e-4)
    assert hybrid.best_fitness < 1.01


def test_pheromone_stays_within_bounds_after_every_update(cal, experts):
    x, y = cal
    res = acomerge(experts, "sn-s", x, y, SMALL, seed=0)
    h = res.history
    assert len(h["tau_min"]) == SMALL.generations
    for lo, hi, tmin, tmax in zip(h["tau_lowest"], h["tau_highest"], h["tau_min"], h["tau_max"]):
        assert tmin * (1 - 1e-6) <= lo <= hi <= tmax * (1 + 1e-6)
    # τ_max tracks the best fitness so far: Q / J_gb
    for tmax, best in zip(h["tau_max"], h["best_so_far"]):
        assert tmax == pytest.approx(SMALL.deposit / best)


# --- IWOA -------------------------------------------------------------------------------

def test_whale_update_moves_all_but_leader():
    gen = torch.Generator().manual_seed(0)
    pos = torch.randn(50, 12, 1, generator=gen)
    leader = torch.randint(0, 12, (50,), generator=gen)
    new = whale_update(pos, leader, a=1.5, inertia=0.9, b=1.0, gen=gen)
    rows = torch.arange(50)
    assert torch.equal(new[rows, leader], pos[rows, leader])
    moved = (new != pos).squeeze(-1)
    moved[rows, leader] = True
    assert moved.float().mean() > 0.99  # every other whale moves (ties have probability ~0)


def test_whale_update_converges_on_leader_when_a_is_zero():
    gen = torch.Generator().manual_seed(1)
    pos = torch.randn(400, 10, 1, generator=gen)
    leader = torch.zeros(400, dtype=torch.long)
    new = whale_update(pos, leader, a=0.0, inertia=1.0, b=1.0, gen=gen)
    at_leader = (new == pos[:, :1]).squeeze(-1)[:, 1:].float().mean()
    assert 0.4 < at_leader < 0.6  # encircling with A = 0 lands on the leader; the spiral (p ≥ 0.5) does not


def test_iwoa_changes_the_search(cal, experts):
    x, y = cal
    both = acomerge(experts, "sn-s", x, y, SMALL, seed=0)
    mmas = acomerge(experts, "sn-s", x, y, dataclasses.replace(SMALL, phases=("mmas",)), seed=0)
    assert sum(both.history["iwoa"]) == SMALL.generations // SMALL.iwoa_every
    assert not any(mmas.history["iwoa"])
    # identical until the first IWOA update, different afterwards
    first = SMALL.iwoa_every
    assert both.history["iteration_best"][:first] == mmas.history["iteration_best"][:first]
    assert both.history["iteration_best"][first:] != mmas.history["iteration_best"][first:]


# --- whole run --------------------------------------------------------------------------

@pytest.mark.parametrize("phases", [("mmas", "iwoa"), ("mmas",), ("iwoa",)])
def test_never_worse_than_the_experts(cal, experts, phases):
    x, y = cal
    res = acomerge(experts, "sn-s", x, y, dataclasses.replace(SMALL, phases=phases), seed=2)
    expert_j = [module_ce("sn-s", e, x, y) for e in experts]
    np.testing.assert_allclose(res.expert_fitness, expert_j, rtol=1e-5)
    assert res.best_fitness <= min(res.expert_fitness)
    assert module_ce("sn-s", res.best_flat, x, y) == pytest.approx(res.best_fitness, rel=1e-5)
    best = res.history["best_so_far"]
    assert all(b2 <= b1 for b1, b2 in zip(best, best[1:]))
    per_gen = SMALL.n_ants if "mmas" in phases else 48
    assert res.evaluations == 3 + SMALL.generations * per_gen


def test_fusion_improves_on_the_experts(cal, experts):
    x, y = cal
    res = acomerge(experts, "sn-s", x, y, SMALL, seed=0)
    assert res.best_fitness < 0.98 * min(res.expert_fitness)
    assert res.best_origin.startswith("generation")


def test_deterministic_for_a_seed(cal, experts):
    x, y = cal
    a = acomerge(experts, "sn-s", x, y, SMALL, seed=5)
    b = acomerge(experts, "sn-s", x, y, SMALL, seed=5)
    c = acomerge(experts, "sn-s", x, y, SMALL, seed=6)
    assert torch.equal(a.best_flat, b.best_flat) and a.history == b.history
    assert not torch.equal(a.best_flat, c.best_flat)


def test_global_rng_untouched(cal, experts):
    x, y = cal
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    acomerge(experts, "sn-s", x, y, dataclasses.replace(SMALL, generations=3), seed=0)
    assert torch.equal(torch.rand(3), expected)


def test_refuses_bad_input(cal, experts):
    x, y = cal
    with pytest.raises(ValueError, match="identical"):
        acomerge(torch.stack([experts[0], experts[0]]), "sn-s", x, y, SMALL)
    with pytest.raises(ValueError, match="543"):
        acomerge(experts[:, :100], "sn-s", x, y, SMALL)
    with pytest.raises(ValueError, match="phases"):
        acomerge(experts, "sn-s", x, y, dataclasses.replace(SMALL, phases=("pso",)))
    bad = experts.clone()
    bad[1, 7] = math.nan
    with pytest.raises(ValueError, match="NaN"):
        acomerge(bad, "sn-s", x, y, SMALL)
