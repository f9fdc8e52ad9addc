"""AcoMerge: fuse K aligned experts into one model by per-parameter search on D_Cal.

The algorithm of the paper (Method, "AcoMerge"), on flat parameter vectors:

Graph and buffer. Parameter index z (T of them) has M candidate values, the
columns of an (M, T) buffer (`buffer.py`: K experts + `copies` Gaussian-perturbed
copies of each, 48 by default). An ant picks one candidate per index; the chosen
values form one candidate model.

Phase 1, MMAS (every generation, `n_ants` ants):
- Transition (paper eq. aco_transition): for each ant and index draw ρ ~ U(0, 1);
  if ρ ≤ ρ0 take the candidate with the largest pheromone, otherwise sample with
  probability ∝ τ^α · η^β. The paper sets η ≡ 1 (`heuristic='constant'`, default).
  ρ0 follows a linear schedule from `q0_start` to `q0_end` (exploration first); the
  paper gives no values, 0.5 → 0.95 gave the lowest D_Cal loss in a small sweep
  (0 → 0.9, 0.3 → 0.98, 0.7 → 0.99, constant 0.9), judged on D_Cal only, never on test data.
  Vectorised (`construct_departures`): one uniform per (index, ant) decides whether the ant
  leaves the greedy candidate there, which has probability (1 − ρ0)·(1 − w_greedy/Σw);
  only those departures are located in the cumulative weights (one `searchsorted`), and a
  generation is kept as the greedy path plus its departures (`Ants`).
  Same distribution as the two-step rule; once the pheromone has concentrated only a
  few decisions per thousand depart. Ties in the argmax go to the lowest candidate index.
- Fitness J(θ) = class-weighted cross-entropy on D_Cal (`fitness.py`), lower is
  better; `AcoMergeResult.best_fitness` is this J. All ants of a generation are
  evaluated in one batched computation; ants that built the same model (those that never
  left the greedy path, more of them as ρ0 grows, and explorers with the same departures)
  share one evaluation.
- Pheromone update (paper eq. pheromone_update): τ ← ρ_evap·τ + (1 − ρ_evap)·Δτ with
  Δτ = Q / J(best) on the nodes of the iteration-best ant and 0 elsewhere. Every
  `gb_every`-th generation the global-best solution deposits instead of the
  iteration best (the MMAS schedule the paper's "periodic global-best update"
  refers to).
- Bounds (standard MMAS, Stützle & Hoos 2000): τ_max = Q / J_gb (the fixed point of
  the update for a node the best solution always visits, J_gb = best J so far) and
  τ_min = τ_max · (1 − p_dec) / ((avg − 1) · p_dec), p_dec = p_best^(1/T), with the
  branching factor avg = M (every index offers all M candidates). τ is clamped to
  [τ_min, τ_max] after initialisation and after every update (so `tau_init` above
  τ_max starts every node at τ_max, the usual MMAS start).

Phase 2, IWOA (one update of all T swarms after every `iwoa_every` generations):
index z is a swarm of its M candidate values, fitness = pheromone, leader = the
candidate with the largest τ (not moved). Call c = 0..N_outer−1 of N_outer =
generations // iwoa_every uses a = 2·(1 − c/N_outer) and inertia w = 1 − 2·(c/N_outer)³.
For every other whale draw p, r1, r2 ~ U(0, 1), A = a(2r1 − 1), C = 2r2:
  p < 0.5, |A| < 1  encircle:  x ← x* − w·A·|C·x* − x|
  p < 0.5, |A| ≥ 1  explore:   x ← x_r − w·A·|C·x_r − x|   (x_r a random member)
  p ≥ 0.5           spiral:    x ← w·|x* − x|·e^{bλ}·cos(2πλ) + x*,  λ ~ U(−1, 1)
The moved values become the candidates of the next MMAS generations (their pheromone stays).

Ablations (config.phases): ('mmas',) — no IWOA, the buffer never changes;
('iwoa',) — no pheromone: the M buffer rows are whole-model whales evaluated by J
every generation, leader = best whale (the paper's "IWOA via ModelSwarm's search
with PSO replaced"), same update rules with a, w scheduled over the generations.

Returned model: the best EVER evaluated, the unperturbed experts included (they are
evaluated before the first generation). Budget: `generations` pheromone updates
(130, one "optimisation step" each, as for the gradient baselines).
Determinism: every draw comes from one seeded torch.Generator; no global RNG. The result
is reproducible for a seed and a thread count (`threads`: torch's intra-op threads).

Where this follows the paper rather than the reference code (REFERENCE_NOTES.md):
- fitness is the weighted CE J itself and deposits are Q/J (the reference uses
  20 − CE and deposits 0.5·(20 − CE));
- η ≡ 1 as the paper states (the reference uses exp(−|w − w_best|); available as
  `heuristic='best_distance'`);
- τ_min from the MMAS formula above (the reference uses τ_max·0.05/((K−1)(0.95 − q)));
- σ = 0.05 for the buffer copies (the reference code uses 0.005);
- no ±5 clipping of IWOA positions unless `clip` is set (the paper does not clip).
Reference bugs avoided:
- bug 1 (one model in all expert slots): the caller passes K different experts and
  `acomerge` refuses duplicate expert rows;
- bug 2 (returns the last generation's best): the best ever, experts included;
- bug 3 (normal draw compared with q0, i.e. probability Φ(q0)): ρ is uniform;
- bug 4 (one forward pass per ant): one batched computation per generation.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm.auto import tqdm

from ..compute import torch_threads
from ..models import n_params
from ..models.train import FC_RATE, LOSSES, check_noise_rate
from .buffer import BUFFER_KINDS, make_buffer
from .fitness import CalibrationFitness
from ..errors import InputError

PHASES = ("mmas", "iwoa")
HEURISTICS = ("constant", "best_distance")


@dataclass
class AcoMergeConfig:
    """Every knob of AcoMerge; defaults are the paper's values where it gives one."""

    n_ants: int = 300  # ants per generation (paper: 300)
    generations: int = 130  # pheromone updates = optimisation steps (paper: 130)
    phases: tuple[str, ...] = PHASES  # ('mmas',) / ('iwoa',) are the ablations
    # buffer
    copies: int = 15  # perturbed copies per expert -> M = K·(1 + copies) = 48 for K = 3
    sigma: float = 0.05  # std of the absolute Gaussian perturbation (paper: 0.05)
    buffer_kind: str = "experts"  # see buffer.py: experts | centroid_random | random
    # MMAS
    alpha: float = 1.0  # pheromone exponent
    beta: float = 1.0  # heuristic exponent (no effect with heuristic='constant')
    heuristic: str = "constant"  # paper: η ≡ 1; 'best_distance': η = exp(−|w − w_best|)
    q0_start: float = 0.5  # ρ0 at the first generation (probability of the greedy choice)
    q0_end: float = 0.95  # ρ0 at the last generation, linear in between
    evaporation: float = 0.5  # ρ_evap in τ ← ρ_evap·τ + (1 − ρ_evap)·Δτ (paper: 0.5)
    deposit: float = 1.0  # Q in Δτ = Q / J
    tau_init: float = 15.0  # initial pheromone, clamped to [τ_min, τ_max] at once
    p_best: float = 0.05  # MMAS probability of rebuilding the best solution at convergence
    gb_every: int = 8  # every n_gb-th update uses the global best (0 = never)
    # IWOA
    iwoa_every: int = 12  # N_mmas: one IWOA update after this many generations
    spiral_b: float = 1.0  # b, the logarithmic-spiral shape constant
    clip: float | None = None  # optional |value| bound on IWOA positions (paper: none)
    # execution
    loss: str = "ce"  # the fitness: weighted CE, or 'gce' / 'fc' (noise-robust; CPU search only, see methods.py)
    noise_rate: float = FC_RATE  # the adjacent label-noise rate ε that the 'fc' fitness assumes (models/train.py)
    chunk: int = 150  # ants per forward chunk of a deeper net (bounds its activations' memory; SN-S bounds its own)
    # torch intra-op threads during the run (0: chosen at its start from the cores free then, see
    # compute.default_threads); the result is deterministic for a seed and a thread count
    threads: int = 1
    # 'cpu' runs `search` (the reference); a GPU ('cuda', 'cuda:N') runs the lockstep engine
    # (lockstep.py), whose results differ from the CPU's in float rounding and random stream
    device: str = "cpu"
    # where the random numbers are drawn on a GPU: 'device' (fast, the default) or 'host' (the CPU
    # generators of the reference, uploaded: a GPU run then differs from the CPU's by rounding only)
    rng: str = "device"

    def validate(self) -> None:
        bad = [p for p in self.phases if p not in PHASES]
        if bad or not self.phases:
            raise InputError(f"phases must be a non-empty subset of {PHASES}, got {self.phases}")
        if self.n_ants < 1 or self.generations < 1:
            raise InputError("n_ants and generations must be at least 1")
        if not (0.0 <= self.q0_start <= 1.0 and 0.0 <= self.q0_end <= 1.0):
            raise InputError("q0_start and q0_end must lie in [0, 1]")
        if not 0.0 <= self.evaporation < 1.0:
            raise InputError("evaporation must lie in [0, 1)")
        if not 0.0 < self.p_best < 1.0:
            raise InputError("p_best must lie in (0, 1)")
        if self.heuristic not in HEURISTICS:
            raise InputError(f"heuristic must be one of {HEURISTICS}")
        if self.buffer_kind not in BUFFER_KINDS:
            raise InputError(f"buffer_kind must be one of {BUFFER_KINDS}")
        if self.iwoa_every < 1 or self.gb_every < 0 or self.deposit <= 0 or self.tau_init <= 0:
            raise InputError("iwoa_every ≥ 1, gb_every ≥ 0, deposit > 0 and tau_init > 0 are required")
        if self.loss not in LOSSES or (self.loss != "ce" and self.device != "cpu"):
            raise InputError(f"loss must be one of {LOSSES}, and 'ce' on a GPU (the lockstep engine's fitness)")
        check_noise_rate(self.noise_rate, "noise_rate")
        if self.chunk < 1 or self.threads < 0:
            raise InputError("chunk must be at least 1 and threads at least 0 (0: chosen from the free cores)")
        if self.device != "cpu" and not self.device.startswith("cuda"):
            raise InputError(f"device must be 'cpu' or 'cuda[:N]', got {self.device!r}")
        if self.rng not in ("device", "host"):
            raise InputError(f"rng must be 'device' or 'host', got {self.rng!r}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class AcoMergeResult:
    best_flat: torch.Tensor  # (T,) the best model ever evaluated
    best_fitness: float  # its J: class-weighted CE on D_Cal (lower is better)
    history: dict[str, list] = field(default_factory=dict)  # per generation, see `acomerge`
    evaluations: int = 0  # candidate models evaluated, experts included
    best_origin: str = ""  # "expert k" or "generation g" (1-based)
    expert_fitness: list[float] = field(default_factory=list)  # J of each unperturbed expert


def mmas_bounds(best_j: float, deposit: float, n_choices: int, n_decisions: int, p_best: float) -> tuple[float, float]:
    """(τ_min, τ_max) of MMAS, see the module docstring."""
    tau_max = deposit / max(best_j, 1e-12)  # J = 0 would mean an infinitely confident perfect fit
    if n_choices < 2:
        return tau_max, tau_max
    p_dec = p_best ** (1.0 / n_decisions)
    return tau_max * (1.0 - p_dec) / ((n_choices - 1) * p_dec), tau_max


@dataclass(frozen=True)
class Ants:
    """One generation's ants as the greedy path and the places they leave it.

    Ant a follows `greedy` (T,) except at index t[d] for every departure d with ant[d] == a, where it
    takes candidate pick[d]. The departures are in (index, ant) order. Late in a search an ant leaves
    the greedy path at a few of the T indices, so this is a few hundred numbers where the dense paths
    (P, T) are 163,000: building, comparing and gathering the ants' models from it costs a fraction
    (issue 30; `dense` gives the (P, T) paths where a caller wants them).
    """

    greedy: np.ndarray  # (T,) int64, argmax τ of every index
    t: np.ndarray  # (D,) int64 index of each departure
    ant: np.ndarray  # (D,) int64 ant of each departure
    pick: np.ndarray  # (D,) int64 candidate taken there
    n_ants: int

    def explorer(self) -> np.ndarray:
        """(P,) bool: which ants left the greedy path somewhere."""
        ex = np.zeros(self.n_ants, dtype=bool)
        ex[self.ant] = True
        return ex

    def rows(self, which: np.ndarray, base: np.ndarray, values: np.ndarray) -> np.ndarray:
        """(len(which), T): `base` (T,) in every row, with each departure of ant which[r] written into row r as
        its entry of `values` (one per departure: the candidate picked, or that candidate's parameter value).
        The ants `which` are distinct."""
        row_of = np.full(self.n_ants, -1, dtype=np.int64)
        row_of[which] = np.arange(which.size)
        out = np.broadcast_to(base, (which.size, base.size)).copy()
        mine = row_of[self.ant] >= 0
        out[row_of[self.ant[mine]], self.t[mine]] = values[mine]
        return out

    def path(self, a: int) -> torch.Tensor:
        """Ant a's path (T,), int64."""
        return torch.from_numpy(self.rows(np.array([a]), self.greedy, self.pick)[0])

    def dense(self) -> torch.Tensor:
        """Every ant's path (P, T), int32."""
        return torch.from_numpy(self.rows(np.arange(self.n_ants), self.greedy.astype(np.int32), self.pick))


def construct_ants(
    tau: torch.Tensor, eta: torch.Tensor | None, q0: float, n_ants: int, gen: torch.Generator,
    alpha: float = 1.0, beta: float = 1.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """`construct_departures` as dense paths (n_ants, T), int32 candidate indices, and which ants
    left the greedy path somewhere (n_ants,), bool."""
    ants = construct_departures(tau, eta, q0, n_ants, gen, alpha, beta)
    return ants.dense(), torch.from_numpy(ants.explorer())


def construct_departures(
    tau: torch.Tensor, eta: torch.Tensor | None, q0: float, n_ants: int, gen: torch.Generator,
    alpha: float = 1.0, beta: float = 1.0,
) -> Ants:
    """Pseudo-random-proportional paths of `n_ants` ants over a (T, M) pheromone, as `Ants`.

    The rule "draw ρ ~ U(0, 1); ρ ≤ q0: argmax τ (ties: lowest index); else roulette on
    w = τ^α·η^β" leaves the greedy candidate g of index t with probability
    π_t = (1 − q0)·(1 − w_g/Σw), and then picks j ≠ g with probability ∝ w_j. One uniform
    u per decision is drawn; u < π_t marks a departure, and u/π_t, uniform on [0, 1) given
    that, is inverted in the cumulative weights of the non-greedy candidates. This is the
    rule's distribution exactly, and once the pheromone has concentrated only a few
    decisions in a thousand leave the greedy path, so only those need a search.
    """
    n_idx, m = tau.shape
    rows = torch.arange(n_idx)
    greedy = tau.argmax(dim=1)
    weight = tau if alpha == 1.0 else tau.pow(alpha)
    if eta is not None:
        weight = weight * (eta if beta == 1.0 else eta.pow(beta))
    weight = weight.to(torch.float64)
    w_greedy = weight[rows, greedy]
    w_others = weight.sum(dim=1) - w_greedy
    leave = ((1.0 - q0) * w_others / (w_others + w_greedy)).to(torch.float32).unsqueeze(1)  # π_t
    others = weight.clone()
    others[rows, greedy] = 0.0  # zero width: a search never lands on the greedy candidate
    cdf = others.cumsum_(dim=1).div_(w_others.unsqueeze(1))
    cdf[:, -1] = 1.0
    u = torch.rand(n_idx, n_ants, generator=gen)
    # The departures' flat positions in (index, ant) order: numpy's flatnonzero finds them in a
    # third of the time of torch's nonzero (an early generation has ~80,000 of 163,000 decisions),
    # and one flat position serves as the index into u without 2-D gathers.
    # (numpy's comparison too: a third of torch's time for the broadcast (T, 1) against (T, P))
    where = np.flatnonzero(np.less(u.numpy(), leave.numpy()))
    t, ant = np.divmod(where, n_ants)
    pick = np.empty(0, dtype=np.int64)
    if where.size:
        # one sorted sequence for all rows (row t spans [2t, 2t + 1]): one search serves every departure
        flat = cdf.add_(2.0 * rows.unsqueeze(1)).reshape(-1)
        t_pt = torch.from_numpy(t)
        v = u.view(-1)[torch.from_numpy(where)].to(torch.float64) / leave.view(-1)[t_pt]
        pick = (torch.searchsorted(flat, 2.0 * t_pt + v, right=True) - t_pt * m).clamp_(max=m - 1).numpy()
    return Ants(greedy.numpy(), t, ant, pick, n_ants)


def whale_update(
    pos: torch.Tensor, leader: torch.Tensor, a: float | torch.Tensor, inertia: float | torch.Tensor, b: float,
    gen: torch.Generator,
    clip: float | None = None,
) -> torch.Tensor:
    """One IWOA move of S independent swarms: pos (S, M, D), leader (S,) whale index -> new (S, M, D).

    p and λ are drawn per whale, r1 and r2 per coordinate; the leader keeps its position.
    """
    s, m, d = pos.shape
    dev = pos.device
    rows = torch.arange(s, device=dev)
    best = pos[rows, leader].unsqueeze(1)  # (S, 1, D)
    here = gen.device  # drawn where the generator lives (a CPU one on a GPU run: --rng host), used on dev
    p = torch.rand(s, m, 1, generator=gen, device=here).to(dev)
    lam = torch.rand(s, m, 1, generator=gen, device=here).to(dev).mul_(2).sub_(1)
    big_a = a * (2 * torch.rand(s, m, d, generator=gen, device=here).to(dev) - 1)
    big_c = 2 * torch.rand(s, m, d, generator=gen, device=here).to(dev)
    partner = torch.randint(0, m, (s, m), generator=gen, device=here).to(dev)
    other = pos[rows.unsqueeze(1), partner]  # (S, M, D) random swarm members
    encircle = best - inertia * big_a * (big_c * best - pos).abs()
    explore = other - inertia * big_a * (big_c * other - pos).abs()
    spiral = inertia * (best - pos).abs() * torch.exp(b * lam) * torch.cos(2 * math.pi * lam) + best
    new = torch.where(p < 0.5, torch.where(big_a.abs() < 1, encircle, explore), spiral)
    if clip is not None:
        new.clamp_(-clip, clip)
    new[rows, leader] = pos[rows, leader]
    return new


@contextlib.contextmanager
def search_threads(threads: int):
    """Torch intra-op threads for a run (`compute.torch_threads`), and the garbage collector paused: a
    generation makes a few hundred short-lived tensors and no reference cycles, and the collections they
    would trigger walk every object of torch & co. (~8 % of a run)."""
    gc_on = gc.isenabled()
    gc.disable()
    try:
        with torch_threads(threads):
            yield
    finally:
        if gc_on:
            gc.enable()


def _evaluate(fitness: Callable[[torch.Tensor], torch.Tensor], flats: torch.Tensor) -> torch.Tensor:
    """Fitness (P,) of flats (P, T); NaN counts as +inf."""
    return torch.nan_to_num(fitness(flats), nan=math.inf)


def evaluate_ants(
    ants: Ants, cand: torch.Tensor, fitness: Callable[[torch.Tensor], torch.Tensor],
) -> torch.Tensor:
    """Fitness (P,) of the ants, their models drawn from `cand` (M, T), in one batch.

    Each distinct model is evaluated once. As q0 grows, more and more ants take the greedy
    candidate (argmax τ) at every index, i.e. rebuild one and the same model: those (the
    non-explorers) share one evaluation. Later in a search most explorers leave the greedy path at
    one to three indices, and about one in eight builds the same model as another ant of its
    generation (often where the pheromone of an index is split between two candidates): those
    share one too. Every ant that built a model takes the J of that model's one row of this one
    call, so sharing is exact by construction on any CPU: no J crosses from one call or batch shape
    to another (in a call of another size a model's J may differ in its last bit, see
    `CalibrationFitness`). The call holds the distinct explorers in ant order, then the greedy
    model if some ant kept to it. The bookkeeping is numpy's on the departures alone (its calls cost
    a few microseconds where torch's cost ten).
    """
    m, n_t = cand.shape
    cells = cand.T.contiguous().numpy().reshape(-1)  # model value of parameter t at candidate j: cells[t·M + j]
    cell = ants.t * m + ants.pick
    explorer = ants.explorer()
    explorers = np.flatnonzero(explorer)
    owner = same_departures(ants, cell, m * n_t, explorers)  # (P,) the first ant with the same model
    firsts = explorers[owner[explorers] == explorers]
    row_of = np.full(ants.n_ants, firsts.size, dtype=np.int64)  # the greedy model's row follows the explorers'
    row_of[firsts] = np.arange(firsts.size)
    # the distinct explorers, then one ant that kept to the greedy path (if any): its row is the greedy model
    which = np.concatenate([firsts, np.flatnonzero(~explorer)[:1]])
    flats = ants.rows(which, cells[np.arange(n_t) * m + ants.greedy], cells[cell])
    j_rows = _evaluate(fitness, torch.from_numpy(flats))
    return j_rows[torch.from_numpy(row_of[owner])]


_CELL_KEYS: dict[int, np.ndarray] = {}


def same_departures(ants: Ants, cell: np.ndarray, n_cells: int, explorers: np.ndarray) -> np.ndarray:
    """(P,) for every ant the first ant (in ant order) that left the greedy path at the same indices
    for the same candidates, i.e. built the same model; each non-explorer is its own. `cell` is
    each departure's t·M + pick, one of `n_cells` = T·M.

    An ant's key is the sum of fixed random weights of its departures' (index, candidate) cells,
    added in index order (so equal departures give equal sums, bit for bit). Ants with equal keys
    are then compared whole, so a collision of keys (never seen) only costs the sharing, never a
    wrong J.
    """
    owner = np.arange(ants.n_ants)
    if explorers.size < 2:
        return owner
    keys = _CELL_KEYS.get(n_cells)
    if keys is None:
        keys = _CELL_KEYS[n_cells] = np.random.default_rng(n_cells).random(n_cells)
    key = np.bincount(ants.ant, weights=keys[cell], minlength=ants.n_ants)[explorers]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    if first.size == explorers.size:
        return owner
    mapped = explorers[first[inverse]]  # the first explorer with the same key
    shared = np.flatnonzero(mapped != explorers)
    involved = np.unique(np.concatenate([explorers[shared], mapped[shared]]))
    rows = ants.rows(involved, ants.greedy, ants.pick)
    if not np.array_equal(rows[np.searchsorted(involved, explorers[shared])], rows[np.searchsorted(involved, mapped[shared])]):
        return owner  # a collision of keys: every ant on its own
    owner[explorers] = mapped
    return owner


def _schedule(c: int, n: int) -> tuple[float, float]:
    """IWOA coefficients (a, inertia) at step c of n."""
    frac = c / n
    return 2.0 * (1.0 - frac), 1.0 - 2.0 * frac**3


def acomerge(
    experts_flat: torch.Tensor,
    arch: str,
    x_cal: np.ndarray,
    y_cal: np.ndarray,
    config: AcoMergeConfig | None = None,
    seed: int = 0,
    progress: bool = False,
    buffer: torch.Tensor | None = None,
    targets: np.ndarray | None = None,
) -> AcoMergeResult:
    """Fuse (K, T) aligned expert vectors into one (T,) vector by AcoMerge on D_Cal = (x_cal, y_cal).

    `buffer` (M, T) replaces the default expert buffer (for the buffer ablation); `targets` (N, 3), each
    row's class probabilities, replace the labels in the fitness (`CalibrationFitness`).
    History (one entry per generation): best_so_far, iteration_best, iteration_mean,
    q0, tau_min, tau_max (the MMAS bounds after the update), tau_lowest, tau_highest (the
    pheromone actually held after the update), iwoa (whether an IWOA update followed).
    The whole-model IWOA ablation records only the first three.
    """
    cfg, experts, cand = checked_inputs(experts_flat, arch, config, seed, buffer)
    fitness = CalibrationFitness(arch, x_cal, y_cal, chunk=cfg.chunk, loss=cfg.loss, noise_rate=cfg.noise_rate,
                                 targets=targets)
    return search(experts, cand, fitness, cfg, seed=seed, progress=progress)


def checked_inputs(
    experts_flat: torch.Tensor, arch: str, config: AcoMergeConfig | None, seed: int, buffer: torch.Tensor | None,
) -> tuple[AcoMergeConfig, torch.Tensor, torch.Tensor]:
    """(config, experts (K, T), buffer (M, T)) after the checks every AcoMerge run needs."""
    cfg = config or AcoMergeConfig()
    cfg.validate()
    experts = torch.as_tensor(experts_flat).detach().to(torch.float32)
    n_t = n_params(arch)
    if experts.dim() != 2 or experts.shape[1] != n_t:
        raise InputError(f"experts must be (K, {n_t}) flat {arch} vectors, got shape {tuple(experts.shape)}")
    if not torch.isfinite(experts).all():
        raise InputError("expert parameters contain NaN or infinity")
    k = experts.shape[0]
    for i in range(k):
        for j in range(i):
            if torch.equal(experts[i], experts[j]):
                raise InputError(f"experts {j} and {i} are identical: fusion needs different models")
    cand = make_buffer(experts, cfg.copies, cfg.sigma, seed, cfg.buffer_kind) if buffer is None else buffer
    cand = torch.as_tensor(cand).detach().to(torch.float32).clone()
    if cand.dim() != 2 or cand.shape[1] != n_t or not torch.isfinite(cand).all():
        raise InputError(f"buffer must be a finite (M, {n_t}) tensor, got shape {tuple(cand.shape)}")
    return cfg, experts, cand


def search(
    experts: torch.Tensor,
    cand: torch.Tensor,
    fitness: Callable[[torch.Tensor], torch.Tensor],
    config: AcoMergeConfig,
    seed: int = 0,
    progress: bool = False,
) -> AcoMergeResult:
    """The search itself, for any batched fitness (P, T) -> (P,) to minimise.

    `acomerge` calls it with the D_Cal cross-entropy; tests call it with toy objectives
    whose optimum is known. The experts are evaluated first; `cand` (M, T) is the buffer.
    """
    config.validate()
    cand = cand.detach().to(torch.float32).clone()
    gen = torch.Generator().manual_seed(seed + 1_000_003)  # independent of the buffer's stream
    with search_threads(config.threads):
        j_experts = _evaluate(fitness, experts)
        best = int(torch.argmin(j_experts))
        result = AcoMergeResult(
            best_flat=experts[best].clone(),
            best_fitness=float(j_experts[best]),
            evaluations=experts.shape[0],
            best_origin=f"expert {best}",
            expert_fitness=[float(v) for v in j_experts],
        )
        run = _run_mmas if "mmas" in config.phases else _run_whole_model_iwoa
        run(config, cand, fitness, gen, result, progress)
    return result


def _keep_if_better(result: AcoMergeResult, j: torch.Tensor, flat_of: Callable[[int], torch.Tensor], g: int) -> bool:
    """Record the best of this generation (its model is flat_of(index)) if it beats the best ever."""
    i = int(torch.argmin(j))
    if float(j[i]) < result.best_fitness:
        result.best_fitness = float(j[i])
        result.best_flat = flat_of(i).clone()
        result.best_origin = f"generation {g + 1}"
        return True
    return False


def _run_mmas(
    cfg: AcoMergeConfig, cand: torch.Tensor, fitness: Callable[[torch.Tensor], torch.Tensor], gen: torch.Generator,
    result: AcoMergeResult, progress: bool,
) -> None:
    m, n_t = cand.shape
    cand_t = cand.T.contiguous()  # (T, M): row z holds the candidates of parameter z (IWOA's swarms)
    idx_rows = torch.arange(n_t)
    # The best expert's path exists when it is in the buffer (default layouts: row k = expert k).
    best_path: torch.Tensor | None = None
    for row in range(m):
        if torch.equal(cand[row], result.best_flat):
            best_path = torch.full((n_t,), row, dtype=torch.long)
            break
    tau_min, tau_max = mmas_bounds(result.best_fitness, cfg.deposit, m, n_t, cfg.p_best)
    tau = torch.full((n_t, m), cfg.tau_init).clamp_(tau_min, tau_max)
    eta = _heuristic(cfg, cand_t, result.best_flat)
    with_iwoa = "iwoa" in cfg.phases
    n_outer = max(1, cfg.generations // cfg.iwoa_every)
    n_calls = 0
    keys = ("best_so_far", "iteration_best", "iteration_mean", "q0", "tau_min", "tau_max", "tau_lowest", "tau_highest", "iwoa")
    hist: dict[str, list] = {k: [] for k in keys}
    bar = tqdm(range(cfg.generations), desc="AcoMerge", disable=not progress, leave=False)
    for g in bar:
        q0 = cfg.q0_start + (cfg.q0_end - cfg.q0_start) * (g / max(1, cfg.generations - 1))
        ants = construct_departures(tau, eta, q0, cfg.n_ants, gen, cfg.alpha, cfg.beta)
        j = evaluate_ants(ants, cand, fitness)
        result.evaluations += cfg.n_ants
        ib = int(torch.argmin(j))
        ib_path = ants.path(ib)
        # _keep_if_better picks the same argmin, ib: its model is ib_path's
        if _keep_if_better(result, j, lambda _: cand.gather(0, ib_path.unsqueeze(0)).squeeze(0), g):
            best_path = ib_path
            eta = _heuristic(cfg, cand_t, result.best_flat)
        # The global-best deposit reinforces the best path's nodes (after an IWOA update those
        # nodes hold moved values; the pheromone belongs to the node, as in the paper's graph).
        use_gb = cfg.gb_every > 0 and (g + 1) % cfg.gb_every == 0 and best_path is not None
        path, j_dep = (best_path, result.best_fitness) if use_gb else (ib_path, float(j[ib]))
        tau.mul_(cfg.evaporation)
        if math.isfinite(j_dep):
            tau[idx_rows, path] += (1.0 - cfg.evaporation) * cfg.deposit / j_dep
        tau_min, tau_max = mmas_bounds(result.best_fitness, cfg.deposit, m, n_t, cfg.p_best)
        tau.clamp_(tau_min, tau_max)
        did_iwoa = with_iwoa and (g + 1) % cfg.iwoa_every == 0 and n_calls < n_outer
        if did_iwoa:
            a, inertia = _schedule(n_calls, n_outer)
            leader = tau.argmax(dim=1)
            cand_t = whale_update(cand_t.unsqueeze(-1), leader, a, inertia, cfg.spiral_b, gen, cfg.clip).squeeze(-1)
            cand = cand_t.T.contiguous()
            n_calls += 1
            eta = _heuristic(cfg, cand_t, result.best_flat)
        finite = j[torch.isfinite(j)]
        for key, value in (
            ("best_so_far", result.best_fitness), ("iteration_best", float(j[ib])),
            ("iteration_mean", float(finite.mean()) if finite.numel() else math.inf),
            ("q0", q0), ("tau_min", tau_min), ("tau_max", tau_max),
            ("tau_lowest", float(tau.min())), ("tau_highest", float(tau.max())), ("iwoa", did_iwoa),
        ):
            hist[key].append(value)
        bar.set_postfix(best=f"{result.best_fitness:.4f}")
    result.history = hist


def _heuristic(cfg: AcoMergeConfig, cand_t: torch.Tensor, best_flat: torch.Tensor) -> torch.Tensor | None:
    if cfg.heuristic == "constant":
        return None  # η ≡ 1
    return torch.exp(-(cand_t - best_flat.unsqueeze(1)).abs())


def _run_whole_model_iwoa(
    cfg: AcoMergeConfig, cand: torch.Tensor, fitness: Callable[[torch.Tensor], torch.Tensor], gen: torch.Generator,
    result: AcoMergeResult, progress: bool,
) -> None:
    """IWOA-only ablation: the buffer rows are whales (whole models), fitness J, leader = lowest J."""
    whales = cand.unsqueeze(0)  # one swarm of M whales in T dimensions
    hist: dict[str, list] = {k: [] for k in ("best_so_far", "iteration_best", "iteration_mean")}
    bar = tqdm(range(cfg.generations), desc="IWOA", disable=not progress, leave=False)
    for g in bar:
        j = _evaluate(fitness, whales[0])
        result.evaluations += whales.shape[1]
        _keep_if_better(result, j, lambda i: whales[0][i], g)
        leader = torch.argmin(j).view(1)
        a, inertia = _schedule(g, cfg.generations)
        whales = whale_update(whales, leader, a, inertia, cfg.spiral_b, gen, cfg.clip)
        finite = j[torch.isfinite(j)]
        hist["best_so_far"].append(result.best_fitness)
        hist["iteration_best"].append(float(j.min()))
        hist["iteration_mean"].append(float(finite.mean()) if finite.numel() else math.inf)
        bar.set_postfix(best=f"{result.best_fitness:.4f}")
    result.history = hist
