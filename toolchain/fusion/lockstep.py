"""AcoMerge for accelerators: R independent runs stepped in lockstep, with no host round trip.

`acomerge.search` is the reference (and the fastest path on a CPU): it reads values back
every generation (`float(j[i])`, `nonzero`) to skip work the data says is not needed, e.g.
the ants that rebuilt the greedy path share one evaluation. On a GPU every such read stops
the host until the device has caught up, and one generation is a few hundred microseconds of
GPU work, so the waiting would dominate. This engine does the same algorithm with every
decision kept on the device as a tensor:

- ant construction is dense (`construct_ants_dense`): every decision's search is done, and
  the departures are picked out with `torch.where` (same distribution as `construct_ants`;
  for the same uniforms the same paths, tested on CPU);
- all ants are evaluated (no greedy-ant sharing, which needs a data-dependent shape);
- the best-so-far model, its path, the MMAS bounds and the global-best deposit are
  selected with `torch.where` per run; the history is kept on the device and read once
  at the end.

Several MCCV runs of one method share the shapes (same architecture, ants and buffer size),
so their generations go into one batched fitness call (`StackedFitness`): on one GPU this is
where the accelerator pays off, since a single SN-S generation is far too small to fill it.
Every run keeps its own torch.Generator, seeded as `acomerge.search` seeds it, so a run's
result does not depend on which runs it was batched with (tested on CPU: R runs together give
the same results as each run alone).

On a GPU a whole generation is one CUDA graph, replayed (see _Lockstep and _Replayed): the
state lives in tensors changed only in place, and the host only says "next generation".

Results on a GPU differ from the CPU reference: other float rounding (GPU GEMMs), and by
default (rng 'device') the CUDA generator gives another random stream than the CPU one for the
same seed. Both draw from the same distributions. With rng 'host' the CPU generators of the
reference are used and their numbers uploaded, so a GPU run differs from the CPU's by float
rounding only (docs/scaling.md).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from ..compute import device_label, resolve_device
from ..data.contracts import N_CLASSES
from ..errors import InputError, first_line
from ..models import batched_logits
from ..models.train import class_weights
from .acomerge import AcoMergeConfig, AcoMergeResult, _schedule, acomerge, checked_inputs, mmas_bounds, whale_update

RNGS = ("device", "host")  # where the search's random numbers are drawn, see `generators`
HISTORY = ("best_so_far", "iteration_best", "tau_lowest", "tau_highest")  # per run and generation, on the device


def run_acomerge_many(
    runs: Sequence[tuple[torch.Tensor, np.ndarray, np.ndarray, int, torch.Tensor | None]], arch: str,
    config: AcoMergeConfig, progress: bool = False, desc: str = "AcoMerge",
) -> list[AcoMergeResult]:
    """Several runs (experts, x_cal, y_cal, seed, buffer or None) of one configuration.

    On the CPU (and for the whole-model IWOA ablation) they run one after the other through
    the reference; on a GPU all of them go through one lockstep search, their ants evaluated
    together in one fitness call per generation.
    """
    config.validate()
    if config.device == "cpu" or "mmas" not in config.phases:
        return [acomerge(e, arch, x, y, config, seed=s, progress=progress, buffer=b) for e, x, y, s, b in runs]
    dev = resolve_device(config.device)
    checked = [checked_inputs(e, arch, config, s, b) for e, _, _, s, b in runs]
    fitness = StackedFitness(arch, [(x, y) for _, x, y, _, _ in runs], dev)
    # One run (fuse) is bound by its ~80 kernel launches, which compiling fuses; a batch of runs
    # (evaluate) fills the GPU, and its shapes and configurations (every method, both calibration
    # sizes) would each cost a compilation of several seconds: it runs the plain steps.
    return search_lockstep([c[1] for c in checked], [c[2] for c in checked], fitness, config,
                           [s for _, _, _, s, _ in runs], dev, progress=progress,
                           desc=f"{desc} x{len(runs)} on {device_label(dev)}", compiled=len(runs) == 1)


class StackedFitness:
    """Class-weighted CE of R runs' candidates on each run's own D_Cal, in one batched call.

    (R, P, T) flats -> (R, P). Calibration sets of different sizes are padded with rows of
    weight 0, so the padding adds nothing. Per run the loss is the same J as
    `CalibrationFitness` (torch's weighted CE, 'mean' reduction), to float rounding.
    """

    def __init__(self, arch: str, cal: Sequence[tuple[np.ndarray, np.ndarray]], device: torch.device | str = "cpu",
                 chunk: int = 0):
        if not cal:
            raise InputError("StackedFitness needs at least one calibration set")
        self.arch, self.device = arch, torch.device(device)
        self.chunk = chunk  # candidates per forward pass (0: all of them at once)
        n = max(len(y) for _, y in cal)
        xs = np.zeros((len(cal), n, cal[0][0].shape[1]), dtype=np.float32)
        ys = np.zeros((len(cal), n), dtype=np.int64)
        ws = np.zeros((len(cal), n), dtype=np.float32)
        for r, (x, y) in enumerate(cal):
            x, y = np.asarray(x, dtype=np.float32), np.asarray(y, dtype=np.int64)
            if x.ndim != 2 or len(x) != len(y) or len(y) == 0 or not np.isfinite(x).all():
                raise InputError(f"calibration set {r}: need finite (N, features) rows with N labels")
            if y.min() < 0 or y.max() >= N_CLASSES:
                raise InputError(f"calibration set {r}: labels must be classes 0..{N_CLASSES - 1}")
            w = class_weights(y).numpy()[y]
            xs[r, : len(y)], ys[r, : len(y)], ws[r, : len(y)] = x, y, w / w.sum()
        self.x = torch.from_numpy(xs).to(self.device)  # (R, N, F)
        self.y = torch.from_numpy(ys).to(self.device)  # (R, N)
        self.w = torch.from_numpy(ws).to(self.device)  # (R, N), each row sums to 1

    @property
    def runs(self) -> int:
        return self.x.shape[0]

    def __call__(self, flats: torch.Tensor) -> torch.Tensor:
        r, p, t = flats.shape
        step = self.chunk or p
        with torch.no_grad():
            parts = [self._loss(flats[:, i : i + step]) for i in range(0, p, step)]
        return torch.cat(parts, dim=1)

    def _loss(self, flats: torch.Tensor) -> torch.Tensor:
        r, p, t = flats.shape
        x = self.x.unsqueeze(1).expand(r, p, *self.x.shape[1:]).reshape(r * p, *self.x.shape[1:])
        logp = F.log_softmax(batched_logits(self.arch, flats.reshape(r * p, t), x), dim=-1)  # (R·P, N, C)
        y = self.y.unsqueeze(1).expand(r, p, -1).reshape(r * p, -1, 1)
        picked = logp.gather(-1, y).squeeze(-1)  # (R·P, N)
        return -(picked.view(r, p, -1) * self.w.unsqueeze(1)).sum(dim=-1)


class GraphedFitness:
    """A fitness replayed from one CUDA graph for inputs of one shape (every generation's ants).

    Why: an SN-S fitness call is about twenty small kernels, and on a GPU launching them one by
    one from Python costs more than running them. The graph launches all of them at once. The
    fitness draws no random numbers, so a replay computes exactly what a call would (bench
    fusion --device cuda reports the difference, 0 expected). Other shapes fall back to the call.
    """

    def __init__(self, fitness: Callable[[torch.Tensor], torch.Tensor], example: torch.Tensor):
        self.fitness = fitness
        self.static_in = example.clone()
        side = torch.cuda.Stream(device=example.device)
        side.wait_stream(torch.cuda.current_stream(example.device))
        with torch.cuda.stream(side):
            for _ in range(2):  # warm-up outside the graph: kernels chosen, workspaces allocated
                fitness(self.static_in)
        torch.cuda.current_stream(example.device).wait_stream(side)
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph, capture_error_mode="thread_local"):  # CPU jobs may run beside it
            self.static_out = fitness(self.static_in)

    def __call__(self, flats: torch.Tensor) -> torch.Tensor:
        if flats.shape != self.static_in.shape:
            return self.fitness(flats)
        self.static_in.copy_(flats)
        self.graph.replay()
        return self.static_out.clone()


def graphed(fitness: Callable[[torch.Tensor], torch.Tensor], example: torch.Tensor
            ) -> Callable[[torch.Tensor], torch.Tensor]:
    """`fitness` as a CUDA graph on a GPU (see GraphedFitness); as it is elsewhere, or where the
    capture fails (then with one warning on stderr)."""
    if example.device.type != "cuda":
        return fitness
    try:
        return GraphedFitness(fitness, example)
    except RuntimeError as e:
        print(f"warning: CUDA graph capture of the fitness failed ({first_line(e)}); running it eagerly",
              file=sys.stderr)
        return fitness


def construct_ants_dense(
    tau: torch.Tensor, eta: torch.Tensor | None, q0: float | torch.Tensor, n_ants: int,
    gens: Sequence[torch.Generator], alpha: float = 1.0, beta: float = 1.0,
) -> torch.Tensor:
    """Paths (R, n_ants, T) int64 of R runs over pheromones tau (R, T, M), without reading back.

    The rule and the uniforms are those of `acomerge.construct_ants` (one uniform per
    decision, (T, n_ants) per run from that run's generator): u < π_t departs, and u/π_t is
    inverted in the cumulative weights of the non-greedy candidates. Here the inversion is
    done for every decision and kept only where the ant departs. q0 may be a float64 tensor of
    one element (the engine's schedule, read on the device). The uniforms are drawn where each
    generator lives and moved to tau's device (`--rng host`: CPU generators on a GPU run).
    Three steps, so that the engine can compile the two without random numbers (see _Lockstep).
    """
    greedy, leave, cdf = ant_weights(tau, eta, q0, alpha, beta)
    return pick_paths(uniforms(gens, tau.shape[1], n_ants, tau.device), greedy, leave, cdf)


def ant_weights(tau: torch.Tensor, eta: torch.Tensor | None, q0: float | torch.Tensor, alpha: float, beta: float
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per decision (R, T): the greedy candidate (R, T, 1), the departure probability π_t (R, T, 1)
    and the cumulative weights of the non-greedy candidates (R, T, M), float64."""
    m = tau.shape[2]
    greedy = tau.argmax(dim=2, keepdim=True)  # (R, T, 1)
    weight = tau if alpha == 1.0 else tau.pow(alpha)
    if eta is not None:
        weight = weight * (eta if beta == 1.0 else eta.pow(beta))
    weight = weight.to(torch.float64)
    w_greedy = weight.gather(2, greedy)
    w_others = weight.sum(dim=2, keepdim=True) - w_greedy
    leave = ((1.0 - q0) * w_others / (w_others + w_greedy)).to(torch.float32)  # (R, T, 1): π_t
    cdf = weight.scatter(2, greedy, 0.0).cumsum(dim=2).div(w_others)
    last = torch.arange(m, device=tau.device) == m - 1
    return greedy, leave, torch.where(last, 1.0, cdf)


def uniforms(gens: Sequence[torch.Generator], n_idx: int, n_ants: int, device: torch.device) -> torch.Tensor:
    """(R, T, P) uniforms, (T, P) from each run's generator, on `device`."""
    return torch.stack([torch.rand(n_idx, n_ants, generator=g, device=g.device) for g in gens]).to(device)


def pick_paths(u: torch.Tensor, greedy: torch.Tensor, leave: torch.Tensor, cdf: torch.Tensor) -> torch.Tensor:
    """The decisions for uniforms u (R, T, P): greedy unless u < π_t, else u/π_t inverted in cdf."""
    m = cdf.shape[2]
    depart = u < leave
    v = u.to(torch.float64) / leave
    pick = torch.searchsorted(cdf, v.contiguous(), right=True).clamp_(max=m - 1)
    return torch.where(depart, pick, greedy).transpose(1, 2)


def _heuristic(cfg: AcoMergeConfig, cand_t: torch.Tensor, best: torch.Tensor) -> torch.Tensor | None:
    """η (R, T, M), or None for the paper's η ≡ 1."""
    if cfg.heuristic == "constant":
        return None
    return torch.exp(-(cand_t - best.unsqueeze(2)).abs())


def generators(seeds: Sequence[int], device: torch.device, rng: str = "device") -> list[torch.Generator]:
    """One generator per run, seeded as `acomerge.search` seeds its own.

    rng 'device': on `device` (fast, graph-safe on a GPU; on a GPU another stream than the CPU's);
    'host': on the CPU, whatever `device` is, so a GPU run draws exactly the CPU reference's
    numbers (uploaded each generation) and differs from it by float rounding only.
    """
    if rng not in RNGS:
        raise InputError(f"rng must be one of {RNGS}, got {rng!r}")
    where = torch.device("cpu") if rng == "host" else device
    return [torch.Generator(device=where).manual_seed(s + 1_000_003) for s in seeds]


class _Lockstep:
    """The state of R lockstep runs on one device, changed only in place.

    Why in place: a CUDA graph records the addresses its kernels read and write, so a
    generation captured once replays correctly only if every later generation finds its
    inputs in the same tensors. The generation counter, the q0 and global-best schedules, the
    IWOA counter and schedule and the history are device tensors for the same reason: a
    generation reads its own index from the device, and the host only says "next".
    `generation()` and `iwoa()` are the only code paths, eager or replayed. A generation is
    three steps: the construction weights, the uniforms, and everything after them; with
    `fused` the first and the last are compiled (see `generation_steps`).
    """

    def __init__(self, ex, cand, fitness, cfg: AcoMergeConfig, gens: list[torch.Generator], fused: bool = False):
        dev = ex.device
        self.cfg, self.fitness, self.gens = cfg, fitness, gens
        self.before_draws, self.after_draws = generation_steps(fused)
        n_runs, (m, n_t) = ex.shape[0], cand.shape[1:]
        self.rows = torch.arange(n_runs, device=dev)
        j_ex = torch.nan_to_num(fitness(ex), nan=math.inf)  # (R, K)
        self.best_k = j_ex.argmin(dim=1)
        self.j_ex = j_ex
        self.best_fit = j_ex.gather(1, self.best_k.unsqueeze(1)).squeeze(1)  # (R,)
        self.best_flat = ex[self.rows, self.best_k]  # (R, T)
        self.best_gen = torch.zeros(n_runs, dtype=torch.long, device=dev)  # 0 = an expert, g = generation g
        # The best expert's path exists when it is in the buffer (the first buffer row equal to it).
        same = (cand == self.best_flat.unsqueeze(1)).all(dim=2)  # (R, M)
        self.has_path = same.any(dim=1)
        self.best_path = same.to(torch.int8).argmax(dim=1, keepdim=True).expand(n_runs, n_t).clone()  # (R, T)
        self.pdec = mmas_bounds(1.0, 1.0, m, n_t, cfg.p_best)[0]  # τ_min / τ_max, a constant of (M, T, p_best)
        tmin, tmax = self.bounds(self.best_fit)
        self.tau = torch.full((n_runs, n_t, m), cfg.tau_init, device=dev)
        self.tau.copy_(torch.minimum(torch.maximum(self.tau, tmin.view(-1, 1, 1)), tmax.view(-1, 1, 1)))
        self.cand = cand.clone()  # (R, M, T)
        self.cand_t = cand.transpose(1, 2).contiguous()  # (R, T, M)
        self.eta = _heuristic(cfg, self.cand_t, self.best_flat)
        n_gen = cfg.generations
        self.q0s = [cfg.q0_start + (cfg.q0_end - cfg.q0_start) * (g / max(1, n_gen - 1)) for g in range(n_gen)]
        self.q0_dev = torch.tensor(self.q0s, dtype=torch.float64, device=dev)
        self.gb_dev = torch.tensor([cfg.gb_every > 0 and (g + 1) % cfg.gb_every == 0 for g in range(n_gen)],
                                   device=dev)
        n_outer = max(1, n_gen // cfg.iwoa_every)
        with_iwoa = "iwoa" in cfg.phases
        self.iwoa_flags = [with_iwoa and (g + 1) % cfg.iwoa_every == 0 and (g + 1) // cfg.iwoa_every <= n_outer
                           for g in range(n_gen)]
        sched = [_schedule(c, n_outer) for c in range(n_outer)]
        self.iwoa_a = torch.tensor([a for a, _ in sched], dtype=torch.float32, device=dev)
        self.iwoa_w = torch.tensor([w for _, w in sched], dtype=torch.float32, device=dev)
        self.g = torch.zeros(1, dtype=torch.long, device=dev)  # the generation being run (0-based)
        self.c = torch.zeros(1, dtype=torch.long, device=dev)  # IWOA calls done
        # the per-generation scalars of a run side by side, so one kernel writes all of them
        self.scalars = torch.zeros(n_runs, n_gen, len(HISTORY), device=dev)
        self.hist = {k: self.scalars[..., i] for i, k in enumerate(HISTORY)}
        self.hist["ants"] = torch.zeros(n_runs, n_gen, cfg.n_ants, device=dev)

    def bounds(self, bf: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        tau_max = self.cfg.deposit / bf.clamp(min=1e-12)
        return tau_max * self.pdec, tau_max

    def generation(self) -> None:
        """Ants, fitness, best-so-far, pheromone update and history of generation self.g; then g += 1."""
        greedy, leave, cdf = self._step("before_draws", _before_draws)
        u = uniforms(self.gens, self.tau.shape[1], self.cfg.n_ants, self.tau.device)
        self._step("after_draws", _after_draws, u, greedy, leave, cdf)

    def _step(self, name: str, plain: Callable, *args):
        """Run a step; where its compiled form fails (no Triton, no C compiler: found on the first
        call, before it changed anything), one warning line and the plain steps from then on."""
        step = getattr(self, name)
        if step is plain:
            return plain(self, *args)
        try:
            return step(self, *args)
        except Exception as e:  # torch.compile raises many types (BackendCompilerFailed, InductorError, ...)
            print(f"warning: compiling the AcoMerge generation failed ({type(e).__name__}: {first_line(e)}); "
                  "running it uncompiled", file=sys.stderr)
            self.before_draws, self.after_draws = generation_steps(False)
            return plain(self, *args)

    def iwoa(self) -> None:
        """One IWOA move of every run's candidates (a and the inertia read from the schedule); c += 1."""
        cfg = self.cfg
        a = self.iwoa_a.index_select(0, self.c).squeeze(0)  # 0-dim: computes in float32 like a Python float
        inertia = self.iwoa_w.index_select(0, self.c).squeeze(0)
        leader = self.tau.argmax(dim=2)  # (R, T)
        moved = torch.stack([
            whale_update(self.cand_t[r].unsqueeze(-1), leader[r], a, inertia, cfg.spiral_b, self.gens[r],
                         cfg.clip).squeeze(-1)
            for r in range(len(self.gens))])
        self.cand_t.copy_(moved)
        self.cand.copy_(moved.transpose(1, 2))
        if self.eta is not None:
            self.eta.copy_(_heuristic(cfg, self.cand_t, self.best_flat))
        self.c.add_(1)


def _before_draws(state: _Lockstep) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The ant-construction weights of generation state.g (see `ant_weights`)."""
    q0 = state.q0_dev.index_select(0, state.g)  # (1,) float64, as the reference's Python float
    return ant_weights(state.tau, state.eta, q0, state.cfg.alpha, state.cfg.beta)


def _after_draws(state: _Lockstep, u: torch.Tensor, greedy: torch.Tensor, leave: torch.Tensor,
                 cdf: torch.Tensor) -> None:
    """Everything of a generation after its uniforms u: paths, fitness, best-so-far, pheromone update,
    history; g += 1. State tensors are written with copy_ (in place, see _Lockstep)."""
    cfg, rows = state.cfg, state.rows
    paths = pick_paths(u, greedy, leave, cdf)  # (R, P, T)
    flats = state.cand.gather(1, paths)  # (R, P, T)
    j = torch.nan_to_num(state.fitness(flats), nan=math.inf)  # (R, P)
    ib = j.argmin(dim=1)
    jb = j.gather(1, ib.unsqueeze(1)).squeeze(1)
    ib_path = paths[rows, ib]  # (R, T)
    better = jb < state.best_fit
    state.best_flat.copy_(torch.where(better.unsqueeze(1), flats[rows, ib], state.best_flat))
    state.best_path.copy_(torch.where(better.unsqueeze(1), ib_path, state.best_path))
    state.best_gen.copy_(torch.where(better, state.g + 1, state.best_gen))
    state.best_fit.copy_(torch.where(better, jb, state.best_fit))
    state.has_path.logical_or_(better)
    if state.eta is not None:
        state.eta.copy_(_heuristic(cfg, state.cand_t, state.best_flat))
    use_gb = state.has_path & state.gb_dev.index_select(0, state.g)
    path = torch.where(use_gb.unsqueeze(1), state.best_path, ib_path)
    j_dep = torch.where(use_gb, state.best_fit, jb)
    # J >= 0, and +inf only where it was NaN (nan_to_num turns an infinite loss into the largest
    # float): Q(1 - ρ)/J is then 0, the reference's "no deposit", without a test of its own
    amount = (1.0 - cfg.evaporation) * cfg.deposit / j_dep
    tau = (state.tau * cfg.evaporation).scatter_add(2, path.unsqueeze(2), amount.view(-1, 1, 1).expand(*path.shape, 1))
    tmin, tmax = state.bounds(state.best_fit)
    state.tau.copy_(torch.clamp(tau, tmin.view(-1, 1, 1), tmax.view(-1, 1, 1)))  # = min(max(τ, τ_min), τ_max)
    # per generation only what is needed later; the statistics are computed once, after the run
    now = torch.stack([state.best_fit, jb, state.tau.amin(dim=(1, 2)), state.tau.amax(dim=(1, 2))], dim=1)
    state.scalars.index_copy_(1, state.g, now.unsqueeze(1))
    state.hist["ants"].index_copy_(1, state.g, j.unsqueeze(1))
    state.g.add_(1)


def generation_steps(fused: bool, backend: str = "inductor") -> tuple[Callable, Callable]:
    """The two random-free steps of a generation, as they are or compiled by torch.compile.

    Why compile: a replayed SN-S generation is about eighty small kernels (the layer norm alone is
    eight), each a few microseconds whatever its size. Inductor fuses the element-wise and
    reduction chains into a handful of kernels (the GEMMs stay cuBLAS's); the uniforms are drawn
    between the two steps, eagerly, by the runs' own generators, so the random streams are those
    of the uncompiled engine. Fused kernels round differently, like any GPU path; the compiled
    steps are captured into the generation's CUDA graph like the plain ones. Compiled once per
    process and shape (dynamic=False), and cached by torch across runs.
    """
    if not fused:
        return _before_draws, _after_draws
    if backend not in _COMPILED:
        _COMPILED[backend] = tuple(torch.compile(f, dynamic=False, backend=backend) for f in (_before_draws, _after_draws))
    return _COMPILED[backend]


_COMPILED: dict[str, tuple[Callable, ...]] = {}


class _Replayed:
    """step() run eagerly, or on a GPU: eagerly `warm` times, then captured once into a CUDA graph
    and replayed from then on (one launch instead of hundreds of small ones per generation).

    The step must change only tensors that live as long as this object (see _Lockstep). The
    eager calls run on a side stream (kernels chosen, cuBLAS workspaces allocated outside the
    capture) and are real steps of the search, not thrown away. The run's own generators are
    registered with the graph, so every replay draws the next numbers of their streams, as an
    eager call would. If the capture fails, one warning line and eager calls from then on; the
    search is the same either way.
    """

    def __init__(self, step: Callable[[], None], device: torch.device, gens: Sequence[torch.Generator],
                 name: str, enabled: bool = True, warm: int = 1):
        self.step, self.device, self.gens, self.name, self.warm = step, device, list(gens), name, warm
        self.enabled = enabled and device.type == "cuda" and all(g.device.type == "cuda" for g in gens)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.calls = 0

    @property
    def replaying(self) -> bool:
        return self.graph is not None

    def __call__(self) -> None:
        self.calls += 1
        if self.graph is not None:
            self.graph.replay()
        elif not self.enabled:
            self.step()
        elif self.calls <= self.warm:
            side = torch.cuda.Stream(device=self.device)
            side.wait_stream(torch.cuda.current_stream(self.device))
            with torch.cuda.stream(side):
                self.step()
            torch.cuda.current_stream(self.device).wait_stream(side)
        else:
            self.graph = self._capture()
            if self.graph is None:
                self.enabled = False
                self.step()
            else:
                self.graph.replay()

    def _capture(self) -> torch.cuda.CUDAGraph | None:
        states = [g.get_state() for g in self.gens]
        try:
            graph = torch.cuda.CUDAGraph()
            for g in self.gens:  # torch >= 2.4: a generator other than the default one, graph-safe
                graph.register_generator_state(g)
            with torch.cuda.graph(graph, capture_error_mode="thread_local"):  # CPU jobs may run beside it
                self.step()
            return graph
        except (RuntimeError, AttributeError) as e:
            for g, s in zip(self.gens, states):
                g.set_state(s)
            print(f"warning: CUDA graph capture of the AcoMerge {self.name} failed ({first_line(e)}); "
                  "running it eagerly", file=sys.stderr)
            return None


def search_lockstep(
    experts: Sequence[torch.Tensor],
    cands: Sequence[torch.Tensor],
    fitness: Callable[[torch.Tensor], torch.Tensor],
    config: AcoMergeConfig,
    seeds: Sequence[int],
    device: torch.device | str = "cpu",
    progress: bool = False,
    desc: str = "AcoMerge",
    cuda_graph: bool = True,
    compiled: bool = True,
) -> list[AcoMergeResult]:
    """R AcoMerge runs (MMAS + IWOA, or MMAS only) in lockstep on `device`.

    experts[r] (K, T) and cands[r] (M, T) are run r's experts and buffer (the same K, M and
    T for every run); `fitness` maps (R, P, T) to (R, P); run r's draws come from its own
    generator seeded with seeds[r] as in `acomerge.search` (where: config.rng, see
    `generators`). The whole-model IWOA ablation is not batched: it runs through
    `acomerge.search`. On a GPU with device-side generators (`cuda_graph`), each whole
    generation is replayed from one CUDA graph and each IWOA move from another (_Replayed);
    with host generators (--rng host) only the fitness is (GraphedFitness), since the
    uniforms come from the CPU. With `compiled`, on a GPU with device-side generators the
    generation's two random-free steps are compiled (`generation_steps`).
    """
    config.validate()
    if "mmas" not in config.phases:
        raise InputError("the lockstep engine runs the MMAS phases; the IWOA-only ablation uses acomerge.search")
    dev = torch.device(device)
    n_runs = len(seeds)
    if not (len(experts) == len(cands) == n_runs) or n_runs == 0:
        raise InputError("one expert set, one buffer and one seed per run are required")
    ex = torch.stack([torch.as_tensor(e, dtype=torch.float32) for e in experts]).to(dev)  # (R, K, T)
    cand = torch.stack([torch.as_tensor(c, dtype=torch.float32) for c in cands]).to(dev)  # (R, M, T)
    gens = generators(seeds, dev, config.rng)
    whole = cuda_graph and config.rng == "device"
    if cuda_graph and not whole:
        fitness = graphed(fitness, torch.zeros(n_runs, config.n_ants, cand.shape[2], device=dev))
    fused = compiled and dev.type == "cuda" and config.rng == "device"
    state = _Lockstep(ex, cand, fitness, config, gens, fused=fused)
    generation = _Replayed(state.generation, dev, gens, "generation", enabled=whole)
    iwoa = _Replayed(state.iwoa, dev, gens, "IWOA move", enabled=whole)
    bar = tqdm(range(config.generations), desc=desc, disable=not progress, leave=False, unit="gen")
    for g in bar:
        generation()
        if state.iwoa_flags[g]:
            iwoa()
    bar.close()
    stacked = dict(state.hist)  # (R, G), "ants" (R, G, P)
    ants = stacked.pop("ants")
    finite = torch.isfinite(ants)
    mean = torch.where(finite, ants, torch.zeros_like(ants)).sum(dim=2) / finite.sum(dim=2)
    stacked["iteration_mean"] = torch.where(finite.any(dim=2), mean, torch.full_like(mean, math.inf))
    stacked["tau_min"], stacked["tau_max"] = state.bounds(stacked["best_so_far"])
    return _results(stacked, state.q0s, state.iwoa_flags, state.best_flat, state.best_fit, state.best_gen,
                    state.best_k, state.j_ex, config)


def _results(hist, q0s, iwoa_flags, best_flat, best_fit, best_gen, best_k, j_ex, cfg) -> list[AcoMergeResult]:
    """Read everything back from the device once and split it per run."""
    per_key = {k: v.double().cpu().tolist() for k, v in hist.items()}  # (R, G) each
    flat, fit = best_flat.cpu(), best_fit.double().cpu().tolist()
    gens, ks, jx = best_gen.cpu().tolist(), best_k.cpu().tolist(), j_ex.double().cpu().tolist()
    out = []
    for r in range(len(fit)):
        history = {k: per_key[k][r] for k in ("best_so_far", "iteration_best", "iteration_mean")}
        history.update(q0=list(q0s), tau_min=per_key["tau_min"][r], tau_max=per_key["tau_max"][r],
                       tau_lowest=per_key["tau_lowest"][r], tau_highest=per_key["tau_highest"][r],
                       iwoa=list(iwoa_flags))
        origin = f"generation {gens[r]}" if gens[r] else f"expert {ks[r]}"
        out.append(AcoMergeResult(best_flat=flat[r].clone(), best_fitness=fit[r], history=history,
                                  evaluations=len(jx[r]) + cfg.n_ants * cfg.generations, best_origin=origin,
                                  expert_fitness=jx[r]))
    return out
