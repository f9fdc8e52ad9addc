"""`acomerge-robust`: AcoMerge searching among experts that were first fine-tuned on D_Cal.

Why (issue 17, item 4): under the leakage-free `traverse` protocol, D_Cal comes from one or two
traverses. AcoMerge over the raw experts fits those rows hard (balanced accuracy about 0.9 on D_Cal)
by recombining parameters of models that never saw the target rover's lunar data, and that
recombination carries over to the other traverses worse than plain gradient fine-tuning of the
Earth expert does. Here every aligned expert first gets the same gradient fine-tuning as
Earth + FullFinetune (`budget.steps` Adam steps at `budget.finetune_lr` on D_Cal), and AcoMerge
then searches a buffer built around those fine-tuned experts (their perturbed copies, σ as
usual), so the recombination starts from models that gradient descent already brought to the
target rover.

Measured on the real files (docs/paper_table.md, 30 runs, |D_Cal| = 150): under the paper protocol
it matches AcoMerge (0.674 vs 0.669 balanced accuracy); under the traverse protocol it ties AcoMerge
(0.492 vs 0.491) and stays below Earth + FullFinetune (0.530), i.e. the issue's goal is not met.
It is kept as the best of the variants measured, not as a solution.

What stays the same as `acomerge` (which remains the paper's algorithm): the search itself
(`acomerge.acomerge`, MMAS + IWOA, 130 generations x 300 ants), the fitness (class-weighted CE
on D_Cal), the buffer size (K experts x (1 + copies)), the returned model (the best ever
evaluated, the fine-tuned experts included), one SN-S of the same shape, hence export and C.

Cost: K x `budget.steps` extra Adam steps (3 x 130 for three experts) before the 130
generations. Fine-tuning keeps the hidden-unit order of each aligned expert (gradient steps
do not permute units), so the Re-Basin alignment still holds for the fine-tuned experts.

The directions measured for this method and what each gave are in docs/paper_table.md,
section "acomerge-robust: what was tried".
"""

from __future__ import annotations

import torch

from ..models import flatten
from .acomerge import AcoMergeConfig
from .baselines.common import model_from_flat
from .buffer import make_buffer
from .finetune import finetune
from .lockstep import run_acomerge_many
from .registry import FusedModel, FusionInputs

NAME = "acomerge-robust"


def finetuned_experts(inp: FusionInputs, loss: str = "ce") -> torch.Tensor:
    """(K, T): each aligned expert fine-tuned on D_Cal as Earth + FullFinetune would be (with `loss`: 'ce', or a
    noise-robust one of models/train.py at the budget's assumed noise rate).

    Expert k uses seed `inp.seed + k`, so the K fine-tunings draw different batches.
    """
    b = inp.budget
    tuned = [
        flatten(finetune(model_from_flat(inp.arch, inp.aligned[k]), inp.x_cal, inp.y_cal, steps=b.steps,
                         lr=b.finetune_lr, seed=inp.seed + k, loss=loss, noise_rate=b.noise_rate))
        for k in range(inp.aligned.shape[0])
    ]
    return torch.stack(tuned).to(torch.float32)


def fit_acomerge_robust_many(inps: list[FusionInputs], config: AcoMergeConfig, name: str = NAME) -> list[FusedModel]:
    """Per calibration draw, fine-tune the aligned experts on D_Cal, then AcoMerge over a buffer around
    them: the fine-tunings one by one (CPU), the searches together (batched on a GPU, see lockstep.py).
    The fine-tuning uses the search's fitness loss (`config.loss`), so a noise-robust variant is robust in both."""
    tuned_all = [finetuned_experts(inp, config.loss) for inp in inps]
    runs = [(tuned, inp.x_cal, inp.y_cal, inp.seed,
             make_buffer(tuned, copies=config.copies, sigma=config.sigma, seed=inp.buffer_seed))
            for inp, tuned in zip(inps, tuned_all)]
    out = []
    for inp, res in zip(inps, run_acomerge_many(runs, inps[0].arch, config, desc=name)):
        details = {"config": config.to_dict(), "best_fitness": res.best_fitness,
                   "best_origin": res.best_origin.replace("expert", "fine-tuned expert"),
                   "evaluations": res.evaluations, "finetuned_expert_fitness": res.expert_fitness,
                   "finetune_steps_per_expert": inp.budget.steps, "history": res.history}
        out.append(FusedModel(method=name, arch=inp.arch, flat=torch.as_tensor(res.best_flat, dtype=torch.float32),
                              curve=[float(v) for v in res.history.get("best_so_far", [])], details=details))
    return out
