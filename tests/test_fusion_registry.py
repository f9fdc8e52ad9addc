"""A new fusion method is one function plus one `register(...)` line: it then runs through
`fleetlab fuse --method` and `fleetlab evaluate --methods`, and both `--help`s list it."""

from __future__ import annotations

import json

import pytest
import torch

from fleetlab.cli import build_parser, main
from fleetlab.fusion import registry
from fleetlab.fusion.registry import FusedModel, FusionInputs
from fleetlab.models import flatten, load_model

NAME = "mean-of-experts"
FITTED: list[torch.Tensor] = []  # every model the throw-away method returned in this process


def fit_mean_of_experts(inputs: FusionInputs) -> FusedModel:
    """Throw-away method: the plain average of the aligned experts (no calibration data used)."""
    flat = inputs.aligned.mean(dim=0)
    FITTED.append(flat.clone())
    return FusedModel(method=NAME, arch=inputs.arch, flat=flat)


@pytest.fixture
def throwaway_method():
    registry.register(NAME, fit_mean_of_experts, "Mean of experts")  # the one registry line
    yield NAME
    registry.unregister(NAME)


def _help(command: str) -> str:
    parser = build_parser(command)
    sub = next(a for a in parser._actions if a.dest == "command")
    return "".join(sub.choices[command].format_help().split())  # argparse may wrap a name at its dashes


def test_help_lists_registered_methods(throwaway_method):
    assert NAME in _help("fuse") and NAME in _help("evaluate")
    registry.unregister(NAME)
    assert NAME not in _help("fuse") and NAME not in _help("evaluate")


def test_register_refuses_bad_and_duplicate_names(throwaway_method):
    with pytest.raises(ValueError, match="registered already"):
        registry.register(NAME, lambda inputs: None)
    with pytest.raises(ValueError, match="lower-case"):
        registry.register("Bad Name", fit_mean_of_experts)
    with pytest.raises(ValueError, match="unknown fusion method"):
        registry.get("telepathy")


def test_throwaway_method_through_fuse(throwaway_method, real_data_dir, tmp_path):
    out = tmp_path / "run"
    assert main(["fuse", "--method", NAME, "--data", str(real_data_dir), "--out", str(out),
                 "--epochs", "1", "--no-progress"]) == 0
    fused, meta = load_model(out / "fused.pt")
    assert meta["method"] == NAME
    experts = [flatten(load_model(p)[0]) for p in sorted((out / "experts").glob("*.pt"))]
    assert len(experts) == 3
    assert torch.allclose(flatten(fused), torch.stack(experts).mean(dim=0))
    report = (out / "report.md").read_text()
    assert "| Mean of experts (fused) |" in report and "method mean-of-experts" in report
    assert not (out / "convergence.png").exists()  # no search history to plot


def test_throwaway_method_through_evaluate(throwaway_method, real_data_dir, tmp_path):
    FITTED.clear()
    out = tmp_path / "eval.json"
    assert main(["evaluate", "--data", str(real_data_dir), "--methods", f"{NAME},earth-ft", "--runs", "2",
                 "--cal-size", "150", "--epochs", "1", "--generations", "3", "--jobs", "1", "--no-progress",
                 "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert list(result["results"]) == ["earth-ft", NAME]  # table order = registration order
    scores = result["results"][NAME]["150"]["balanced_accuracy"]
    # the average of fixed experts does not depend on the draw's calibration rows: both runs score
    # the same model, on their own test rows
    assert len(scores["runs"]) == 2 and all(0.0 <= s <= 1.0 for s in scores["runs"])
    assert len(FITTED) == 2 and torch.equal(FITTED[0], FITTED[1])
