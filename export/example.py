"""Regenerate the committed example bundle `firmware_c/bundles/example` from simulator data.

    python -m fleetlab.cli.example_bundle [--out DIR] [--seed 1] [--scale 0.3]

Simulates the built-in scenario (as `fleetlab simulate --seed SEED --scale SCALE`) into a temporary folder, trains an SN-S on
its `earth` and `target` windows (Adam, the expert hyper-parameters, fixed seed, one thread so
the result is the same on every machine), and exports it with the project's own exporter:
test vectors drawn from the simulated windows plus the edge cases, accuracy report included.
Nothing from the real Fleet-To-Lab files goes into the bundle.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import torch

from fleetlab.models.train import EXPERT_EPOCHS

TRAIN_ROLES = ("earth", "target")
N_VECTORS = 1200


def make_example(out: Path, seed: int = 1, scale: float = 0.3, epochs: int = EXPERT_EPOCHS, keep: Path | None = None) -> Path:
    """Simulate, train, export into `out`; with `keep`, also leave the model and the simulated data there."""
    from fleetlab.data.dataset import load_dataset
    from fleetlab.data.simulator.scenario import write_scenario
    from fleetlab.models import build, save_model
    from fleetlab.models.train import train_classifier

    from .bundle import check_bundle, export_bundle
    from .vectors import draw_inputs

    with tempfile.TemporaryDirectory(prefix="fleetlab-example-") as tmp:
        sim = Path(tmp) / "sim"
        write_scenario(sim, seed, scale, progress=True)  # what `fleetlab simulate --seed --scale` writes
        ds = load_dataset(sim)
        x = np.concatenate([ds.xy(r)[0] for r in TRAIN_ROLES])
        y = np.concatenate([ds.xy(r)[1] for r in TRAIN_ROLES])
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            model = train_classifier(build("sn-s", seed=seed), x, y, epochs=epochs, seed=seed, desc="train SN-S")
        finally:
            torch.set_num_threads(threads)
        meta = {
            "trained_on": f"fleetlab simulate --seed {seed} --scale {scale}, roles {', '.join(TRAIN_ROLES)}",
            "windows": int(len(y)), "epochs": epochs, "seed": seed, "made_by": "python -m fleetlab.cli.example_bundle",
        }
        model_path = save_model(Path(tmp) / "example_sns.pt", model, meta)
        all_windows = np.concatenate([ds.xy(r)[0] for r in ds.roles])
        inputs = draw_inputs(N_VECTORS, all_windows, seed)
        sources = {"data": [f"fleetlab simulate --seed {seed} --scale {scale}"], "seed": seed, "kind": "dataset windows"}
        b = export_bundle(model, out, inputs=inputs, meta=meta, model_path=model_path, data_dirs=[sim],
                          vector_sources=sources)
        _rewrite_manifest_paths(b.path, str(sim))  # keep the committed files free of temporary paths
        if keep is not None:
            import shutil

            keep.mkdir(parents=True, exist_ok=True)
            shutil.copy(model_path, keep / model_path.name)
            shutil.copytree(sim, keep / "sim", dirs_exist_ok=True)
    for line in check_bundle(out):
        print(f"  ok  {line}")
    return out


def _rewrite_manifest_paths(out: Path, sim_dir: str) -> None:
    """Replace temporary paths in manifest.json and the accuracy report, then re-hash the files."""
    import json

    from . import manifest

    label = "fleetlab-simulate-output"
    for name in ("accuracy.json", "accuracy.md"):
        p = out / name
        if p.exists():
            p.write_text(p.read_text().replace(sim_dir, label))
    m = json.loads((out / manifest.MANIFEST).read_text())
    m["source_model"]["path"] = "example_sns.pt (temporary; python -m fleetlab.cli.example_bundle rebuilds it)"
    m["files"] = manifest.file_entries(out, list(m["files"]))
    manifest.write_manifest(out, m)
