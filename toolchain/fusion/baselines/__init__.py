"""The paper's baselines for AcoMerge, each under the same budget of 130 optimisation steps.

| method        | module        | searches                                          |
|---------------|---------------|---------------------------------------------------|
| model-base    | finetuned     | a fresh model, Adam on D_Cal                       |
| earth-ft      | finetuned     | the Earth expert, fully fine-tuned on D_Cal        |
| joint-ft      | finetuned     | a model trained on Earth ∪ fleet data, fine-tuned  |
| adamerging    | adamerging    | per-tensor task-vector coefficients, Adam          |
| evomerge      | evomerge      | layer-wise DARE-TIES weights/densities, CMA-ES     |
| modelswarm    | modelswarm    | PSO over AcoMerge's 48-model buffer                |
| distill       | distill       | a fresh student, KD from the experts + weighted CE |

Merging baselines take the Re-Basin-aligned expert flats (K, T), Earth expert first.
"""

from .adamerging import adamerging
from .common import BUDGET_STEPS, merge_base, model_from_flat
from .dare_ties import dare, dare_ties_merge, disjoint_merge, elect_sign, ties_merge, ties_trim
from .distill import distill
from .evomerge import evomerge
from .finetuned import earth_finetune, joint_finetune, model_base, train_joint
from .modelswarm import SwarmConfig, modelswarm, pso

__all__ = [
    "BUDGET_STEPS", "SwarmConfig", "adamerging", "dare", "dare_ties_merge", "disjoint_merge", "distill",
    "earth_finetune", "elect_sign", "evomerge", "joint_finetune", "merge_base", "model_base", "model_from_flat",
    "modelswarm", "pso", "ties_merge", "ties_trim", "train_joint",
]
