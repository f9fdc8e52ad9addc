"""The paper's fusion methods and ablations, each registered under its name.

Every method fits on one calibration draw through `registry.FusionInputs` and returns a
`registry.FusedModel`. Registration order is the order of the paper's table.
"""

from __future__ import annotations

import dataclasses

import torch

from ..models import flatten
from . import baselines as bl
from .acomerge import AcoMergeConfig, AcoMergeResult, acomerge
from .buffer import make_buffer
from .label_audit import crossval_probabilities, flag_labels
from .lockstep import run_acomerge_many
from .registry import Budget, FusedModel, FusionInputs, register
from .robust import fit_acomerge_robust_many
from ..errors import InputError


def make_run_buffer(aligned: torch.Tensor, kind: str, seed: int, sigma: float = Budget.sigma,
                    copies: int = Budget.copies) -> torch.Tensor:
    """The 48-model buffer (3 experts x (1 + 15)) that AcoMerge and ModelSwarm search."""
    return make_buffer(aligned, copies=copies, sigma=sigma, seed=seed, kind=kind)


def fleet_ablation_buffer(method: str, aligned: torch.Tensor, seed: int, sigma: float = Budget.sigma,
                          copies: int = Budget.copies) -> tuple[torch.Tensor, torch.Tensor]:
    """(kept experts, buffer) of a fleet-ablation method: the Earth expert (row 0) alone, or the
    fleet experts (rows 1..) alone, each with enough perturbed copies to keep the buffer at about
    its full size K·(1 + copies) (exactly 48 for three experts)."""
    n_all = aligned.shape[0]
    if n_all < 2:
        raise InputError(f"{method} needs the Earth expert and at least one fleet expert, got {n_all} expert(s)")
    kept = aligned[:1] if method == "acomerge-earth-only" else aligned[1:]
    kept_copies = max(0, round(n_all * (1 + copies) / kept.shape[0]) - 1)
    return kept, make_buffer(kept, copies=kept_copies, sigma=sigma, seed=seed)


def aco_config(budget: Budget, phases: tuple[str, ...] | None = None, loss: str = "ce") -> AcoMergeConfig:
    """AcoMerge's configuration under `budget` (the paper's values for everything else)."""
    cfg = dataclasses.replace(AcoMergeConfig(), generations=budget.steps, n_ants=budget.ants, copies=budget.copies,
                              sigma=budget.sigma, threads=budget.threads, device=budget.device,
                              rng=budget.rng, loss=loss, noise_rate=budget.noise_rate)
    return dataclasses.replace(cfg, phases=phases) if phases else cfg


def _flat(name: str, inp: FusionInputs, flat: torch.Tensor) -> FusedModel:
    return FusedModel(method=name, arch=inp.arch, flat=torch.as_tensor(flat, dtype=torch.float32))


# --- fine-tuned and trained-from-scratch references ---
def _model_base(inp: FusionInputs) -> FusedModel:
    model = bl.model_base(inp.arch, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps)
    return _flat("model-base", inp, flatten(model))


def _earth_ft(inp: FusionInputs) -> FusedModel:
    earth = bl.model_from_flat(inp.arch, inp.experts[0])
    tuned = bl.earth_finetune(earth, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps, lr=inp.budget.finetune_lr)
    return _flat("earth-ft", inp, flatten(tuned))


def _joint_ft(inp: FusionInputs) -> FusedModel:
    joint = bl.model_from_flat(inp.arch, inp.joint)
    tuned = bl.joint_finetune(joint, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps, lr=inp.budget.finetune_lr)
    return _flat("joint-ft", inp, flatten(tuned))


# --- merging baselines over the aligned experts ---
def _adamerging(inp: FusionInputs) -> FusedModel:
    return _flat("adamerging", inp, bl.adamerging(inp.aligned, inp.arch, inp.x_cal, inp.y_cal, inp.seed,
                                                  steps=inp.budget.steps))


def _evomerge(inp: FusionInputs) -> FusedModel:
    return _flat("evomerge", inp, bl.evomerge(inp.aligned, inp.arch, inp.x_cal, inp.y_cal, inp.seed,
                                              steps=inp.budget.steps))


def _modelswarm(inp: FusionInputs) -> FusedModel:
    b = inp.budget
    buffer = make_run_buffer(inp.aligned, "experts", inp.buffer_seed, b.sigma, b.copies)
    return _flat("modelswarm", inp, bl.modelswarm(inp.aligned, inp.arch, inp.x_cal, inp.y_cal, inp.seed,
                                                  steps=b.steps, buffer=buffer))


def _distill(inp: FusionInputs) -> FusedModel:
    student = bl.distill(inp.experts, inp.arch, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps)
    return _flat("distill", inp, flatten(student))


# --- AcoMerge and its ablations ---
# Each is a `fit_many` (several calibration draws of one budget at once: on a GPU their
# generations share one batched fitness call, see lockstep.py); `fit` is the one-draw case.
def _aco_runs(name: str, inps: list[FusionInputs], kept_buffers: list[tuple[torch.Tensor, torch.Tensor]],
              phases: tuple[str, ...] | None = None, loss: str = "ce") -> list[FusedModel]:
    cfg = aco_config(inps[0].budget, phases, loss)
    runs = [(kept, inp.x_cal, inp.y_cal, inp.seed, buffer) for inp, (kept, buffer) in zip(inps, kept_buffers)]
    return [_aco_model(name, inp.arch, cfg, res) for inp, res in zip(inps, run_acomerge_many(runs, inps[0].arch, cfg,
                                                                                            desc=name))]


def _aco_model(name: str, arch: str, cfg: AcoMergeConfig, res: AcoMergeResult) -> FusedModel:
    details = {"config": dataclasses.asdict(cfg), "best_fitness": res.best_fitness, "best_origin": res.best_origin,
               "evaluations": res.evaluations, "expert_fitness": res.expert_fitness, "history": res.history}
    return FusedModel(method=name, arch=arch, flat=torch.as_tensor(res.best_flat, dtype=torch.float32),
                      curve=[float(v) for v in res.history.get("best_so_far", [])], details=details)


def _one(fit_many):
    """The one-draw `fit` of a `fit_many`."""
    def fit(inp: FusionInputs) -> FusedModel:
        return fit_many([inp])[0]
    fit.__name__ = fit.__qualname__ = fit_many.__name__.replace("_many", "")
    return fit


def _aco_on_buffer(name: str, kind: str = "experts", phases: tuple[str, ...] | None = None, loss: str = "ce"):
    def fit_many(inps: list[FusionInputs]) -> list[FusedModel]:
        b = inps[0].budget
        return _aco_runs(name, inps, [(inp.aligned, make_run_buffer(inp.aligned, kind, inp.buffer_seed, b.sigma, b.copies))
                                      for inp in inps], phases, loss)
    fit_many.__name__ = fit_many.__qualname__ = f"fit_{name.replace('-', '_')}_many"
    return fit_many


def _acomerge_robust_many(inps: list[FusionInputs]) -> list[FusedModel]:
    return fit_acomerge_robust_many(inps, aco_config(inps[0].budget))


def _aco_fleet_ablation(name: str):
    def fit_many(inps: list[FusionInputs]) -> list[FusedModel]:
        b = inps[0].budget
        return _aco_runs(name, inps, [fleet_ablation_buffer(name, inp.aligned, inp.buffer_seed, b.sigma, b.copies)
                                      for inp in inps])
    fit_many.__name__ = fit_many.__qualname__ = f"fit_{name.replace('-', '_')}_many"
    return fit_many


# --- noise-robust variants (issue 46; docs/paper_table.md, "Noisy calibration labels") ---
def _earth_ft_gce(inp: FusionInputs) -> FusedModel:
    earth = bl.model_from_flat(inp.arch, inp.experts[0])
    tuned = bl.earth_finetune(earth, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps, lr=inp.budget.finetune_lr,
                              loss="gce")
    return _flat("earth-ft-gce", inp, flatten(tuned))


def _acomerge_gce(inp: FusionInputs) -> FusedModel:
    """AcoMerge whose fitness is the bounded GCE: the CPU search (the GPU engine's fitness is CE only)."""
    return _aco_on_buffer("acomerge-gce", loss="gce")([dataclasses.replace(inp, budget=dataclasses.replace(
        inp.budget, device="cpu"))])[0]


def _earth_ft_fc(inp: FusionInputs) -> FusedModel:
    earth = bl.model_from_flat(inp.arch, inp.experts[0])
    tuned = bl.earth_finetune(earth, inp.x_cal, inp.y_cal, inp.seed, steps=inp.budget.steps, lr=inp.budget.finetune_lr,
                              loss="fc", noise_rate=inp.budget.noise_rate)
    return _flat("earth-ft-fc", inp, flatten(tuned))


def _on_cpu(inps: list[FusionInputs]) -> list[FusionInputs]:
    """The draws with their budget on the CPU: the GPU engine's fitness is CE only."""
    return [dataclasses.replace(inp, budget=dataclasses.replace(inp.budget, device="cpu")) for inp in inps]


def _acomerge_fc_many(inps: list[FusionInputs]) -> list[FusedModel]:
    """AcoMerge whose fitness is the forward-corrected CE at the budget's assumed noise rate (the CPU search)."""
    return _aco_on_buffer("acomerge-fc", loss="fc")(_on_cpu(inps))


def _acomerge_robust_fc_many(inps: list[FusionInputs]) -> list[FusedModel]:
    """acomerge-robust with the forward-corrected loss in both the experts' fine-tuning and the search's fitness."""
    inps = _on_cpu(inps)
    return fit_acomerge_robust_many(inps, aco_config(inps[0].budget, loss="fc"), name="acomerge-robust-fc")


def _acomerge_audit_many(inps: list[FusionInputs]) -> list[FusedModel]:
    """AcoMerge on D_Cal without the labels a confident-learning audit flags (fusion/label_audit.py)."""
    kept, flagged = [], []
    for inp in inps:
        probs = crossval_probabilities(inp.arch, inp.experts[0], inp.x_cal, inp.y_cal, inp.seed, inp.budget.steps,
                                       inp.budget.finetune_lr)
        bad = flag_labels(inp.y_cal, probs)
        kept.append(dataclasses.replace(inp, x_cal=inp.x_cal[~bad], y_cal=inp.y_cal[~bad]))
        flagged.append(int(bad.sum()))
    out = _aco_on_buffer("acomerge-audit")(kept)
    for fused, n, inp in zip(out, flagged, inps):
        fused.details["audit"] = {"flagged": n, "of": int(len(inp.y_cal))}
    return out


def _acomerge_vo_many(inps: list[FusionInputs]) -> list[FusedModel]:
    """AcoMerge whose fitness takes each label's class probabilities from its VO reading as the target
    (`FusionInputs.y_cal_probs`, data/label_noise.py; the rows keep their labels' class weights), without
    the windows whose VO did not converge. With exact labels the probabilities are certain and this is
    AcoMerge bit for bit. The CPU search: the GPU engine's fitness takes hard labels."""
    out = []
    for inp in _on_cpu(inps):
        measured = inp.y_cal_probs.sum(axis=1) > 0
        if not measured.any():
            raise InputError(f"VO did not converge on any of D_Cal's {measured.size} windows: no label to fuse on")
        cfg = aco_config(inp.budget)
        buffer = make_run_buffer(inp.aligned, "experts", inp.buffer_seed, cfg.sigma, cfg.copies)
        res = acomerge(inp.aligned, inp.arch, inp.x_cal[measured], inp.y_cal[measured], cfg, seed=inp.seed,
                       buffer=buffer, targets=inp.y_cal_probs[measured])
        fused = _aco_model("acomerge-vo", inp.arch, cfg, res)
        fused.details["vo"] = {"rows_without_measurement": int((~measured).sum()), "of": int(measured.size)}
        out.append(fused)
    return out


def _register_many(name: str, fit_many, label: str, group: str, needs_label_probs: bool = False) -> None:
    register(name, _one(fit_many), label, group, fit_many=fit_many, needs_label_probs=needs_label_probs)


# One line per method: name, fit, label, table group.
register("joint-ft", _joint_ft, "Joint + FullFinetune", "Fine-tuned", needs_joint=True)
register("earth-ft", _earth_ft, "Earth + FullFinetune", "Fine-tuned")
register("model-base", _model_base, "Model Base", "Fine-tuned")
register("adamerging", _adamerging, "AdaMerging", "Merging")
register("evomerge", _evomerge, "Evolutionary Merge", "Merging")
register("modelswarm", _modelswarm, "ModelSwarm", "Merging")
_register_many("acomerge", _aco_on_buffer("acomerge"), "AcoMerge", "Merging")
# not in the paper: AcoMerge over experts fine-tuned on D_Cal first (issue 17, fusion/robust.py)
_register_many("acomerge-robust", _acomerge_robust_many, "AcoMerge-robust", "Merging")
register("distill", _distill, "Ensemble distillation", "Distillation")
_register_many("mmas-only", _aco_on_buffer("mmas-only", phases=("mmas",)), "MMAS only", "Ablation")
# whole-model IWOA over the buffer (ModelSwarm's search, PSO replaced)
register("iwoa-only", _one(_aco_on_buffer("iwoa-only", phases=("iwoa",))), "IWOA only", "Ablation")
# Buffer ablation: AcoMerge on other buffers than its own expert buffer.
_register_many("buffer-centroid-random", _aco_on_buffer("buffer-centroid-random", "centroid_random"),
               "buffer: experts×3 + centroid-random×45", "Buffer ablation")
_register_many("buffer-random", _aco_on_buffer("buffer-random", "random"), "buffer: random×48", "Buffer ablation")
# Fleet ablation: AcoMerge with some experts left out of its buffer (same buffer size): what the
# fleet contributes beyond the Earth expert and the search itself.
_register_many("acomerge-earth-only", _aco_fleet_ablation("acomerge-earth-only"), "AcoMerge, Earth expert only",
               "Fleet ablation")
_register_many("acomerge-fleet-only", _aco_fleet_ablation("acomerge-fleet-only"), "AcoMerge, fleet experts only",
               "Fleet ablation")
# Noise-robust variants: opt-in (registry.OPT_IN_GROUPS), for calibration labels from visual odometry.
register("earth-ft-gce", _earth_ft_gce, "Earth + FullFinetune (GCE)", "Noise-robust")
register("acomerge-gce", _acomerge_gce, "AcoMerge (GCE fitness)", "Noise-robust")
_register_many("acomerge-audit", _acomerge_audit_many, "AcoMerge (label audit)", "Noise-robust")
register("earth-ft-fc", _earth_ft_fc, "Earth + FullFinetune (forward-corrected)", "Noise-robust")
_register_many("acomerge-fc", _acomerge_fc_many, "AcoMerge (forward-corrected fitness)", "Noise-robust")
_register_many("acomerge-robust-fc", _acomerge_robust_fc_many, "AcoMerge-robust (forward-corrected)", "Noise-robust")
_register_many("acomerge-vo", _acomerge_vo_many, "AcoMerge (VO class probabilities)", "Noise-robust",
               needs_label_probs=True)
