"""The dataset folder a command was given, loaded, with its dropped rows said on stderr.

Rows holding NaN or infinity never reach a model: the CSV reader drops and counts them
(`Dataset.rejected_nonfinite`). A command that trains, evaluates or exports on the folder says so in
one line, so that a user's damaged log is never lost without a word; `fleetlab data info` counts
them per file, and the fuse and evaluate reports record the count."""

from __future__ import annotations

import sys
from pathlib import Path

from ..data.dataset import Dataset, load_dataset


def load(path: Path | str) -> Dataset:
    dataset = load_dataset(path)
    if dataset.rejected_nonfinite:
        print(f"{path}: {dataset.rejected_nonfinite} rows holding NaN or infinity dropped "
              f"('fleetlab data info {path}' counts them per file)", file=sys.stderr)
    return dataset
