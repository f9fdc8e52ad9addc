"""The float tolerance of a bundle (issue 42 item 4): a float32 error bound that follows from the network
(export/f32_bound.py, docs/fixed_point.md "The float path: tolerance"), recorded once in manifest.json and read by
every float check; a failed export leaves no half-written bundle and its error line is not overwritten by the
progress bar."""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import warnings

import numpy as np
import pytest
import torch
from torch.nn import functional as F

from fleetlab.export import f32_bound
from fleetlab.export.bundle import check_bundle, export_bundle
from fleetlab.export.f32_bound import GELU_REL, U, excess, float_bound, float_tolerance, recorded_tolerance
from fleetlab.export.onnx_export import export_onnx, onnx_logits
from fleetlab.export.vectors import draw_inputs, read_vectors
from fleetlab.models import build, save_model
from fleetlab.paths import repo_root

from small_models import quick_model

EXAMPLE = repo_root() / "firmware_c" / "bundles" / "example"


def _exact(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    """The float32 network evaluated in float64 (its rounding is 2^29 times finer than float32's)."""
    m64 = copy.deepcopy(model).double().eval()
    with torch.no_grad():
        return m64(torch.from_numpy(np.asarray(x, np.float64))).numpy()


def _stressed() -> torch.nn.Module:
    """24,9 whose hidden pre-activations share large offsets (first block: +60 on every bias, second: weights x 4):
    LayerNorm cancels them, the hardest case for its rounding (mean(h^2) >> variance)."""
    m = quick_model("24,9")
    with torch.no_grad():
        m.linears[0].bias += 60.0
        m.linears[1].weight *= 4.0
    return m.eval()


MODELS = {"sn-s": lambda: quick_model("sn-s"), "24,9": lambda: quick_model("24,9"),
          "sn-d": lambda: quick_model("sn-d"), "stressed 24,9": _stressed}


@pytest.mark.parametrize("name", list(MODELS))
def test_each_runtime_is_within_the_bound_of_the_exact_result(name, tmp_path):
    """The bound is a bound: torch and onnxruntime each stay within E of the exact logits, on every logit of 1,200
    vectors (the edge rows at the int16 rails included); so two of them differ by at most 2 E, the tolerance."""
    model = MODELS[name]().eval()
    x = draw_inputs(1200, None, seed=11)
    exact = _exact(model, x)
    logits, e = float_bound(model, x)
    assert np.allclose(logits, exact, rtol=1e-9, atol=1e-9)
    with torch.no_grad():
        got_torch = model(torch.from_numpy(x)).numpy()
    export_onnx(model, tmp_path / "m.onnx")
    got_ort = onnx_logits(tmp_path / "m.onnx", x)
    for runtime, got in (("torch", got_torch), ("onnxruntime", got_ort)):
        err = np.abs(got.astype(np.float64) - exact)
        assert (err <= e).all(), (runtime, float((err / e).max()))
        print(f"{name} {runtime}: max error / bound {float((err / e).max()):.3g}, max error {err.max():.3g}, "
              f"median bound {np.median(e):.3g}")


def test_gelu_of_every_runtime_is_within_the_assumed_error():
    """The one assumption of the bound: every runtime's GELU is within GELU_REL |y| of the exact GELU (torch's
    F.gelu, onnxruntime's Div/Erf/Add/Mul graph of the exported model, the C form 0.5 y (1 + erf(y c)) with
    slipest_erf_f32's error, below 1e-7, added to a correctly rounded erf)."""
    from scipy.special import erf

    y = np.concatenate([np.linspace(-9, 9, 400_001), np.geomspace(1e-6, 9, 20_001)]).astype(np.float32)
    y = np.concatenate([y, -y])
    yd = y.astype(np.float64)
    exact = 0.5 * yd * (1.0 + erf(yd / math.sqrt(2.0)))
    limit = GELU_REL * np.abs(yd)

    with torch.no_grad():
        got_torch = F.gelu(torch.from_numpy(y)).numpy().astype(np.float64)

    class Gelu(torch.nn.Module):
        def forward(self, t):
            return F.gelu(t)

    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(Gelu(), (torch.zeros(2),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {0: "n"}, "y": {0: "n"}}, opset_version=17, dynamo=False)
    import onnxruntime as ort

    got_ort = ort.InferenceSession(buf.getvalue(), providers=["CPUExecutionProvider"]).run(None, {"x": y})[0]
    # the C form in float32, erf correctly rounded; slipest_erf_f32 adds at most 1e-7 (test_erf), 0.5 |y| 1e-7 here
    t = (y * np.float32(0.707106781)).astype(np.float32)
    c_form = (np.float32(0.5) * y * (np.float32(1.0) + erf(t.astype(np.float64)).astype(np.float32))).astype(np.float32)
    c_err = np.abs(c_form.astype(np.float64) - exact) + 0.5 * np.abs(yd) * 1e-7
    for runtime, err in (("torch", np.abs(got_torch - exact)), ("onnxruntime", np.abs(got_ort - exact)),
                         ("C form", c_err)):
        assert (err <= limit).all(), (runtime, float((err / np.maximum(np.abs(yd), 1e-30)).max() / U))


def test_dot_product_term_grows_with_fan_in():
    """gamma_n = n u / (1 - n u): the rounding bound of a dot product grows with its length."""
    assert f32_bound.gamma(13) == pytest.approx(13 * U, rel=1e-6)
    assert f32_bound.gamma(257) > 19 * f32_bound.gamma(13)
    x = draw_inputs(200, None, seed=2)
    narrow = float_tolerance(quick_model("24,9"), x)["median_abs_bound"]
    wide = float_tolerance(quick_model("sn-d"), x)["median_abs_bound"]
    assert wide > narrow


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("tol") / "bundle"
    model = quick_model("24,9")
    b = export_bundle(model, out, inputs=draw_inputs(1000, None, seed=3))
    return model, b


def test_the_manifest_records_the_tolerance_and_its_rule(exported):
    model, b = exported
    m = json.loads((b.path / "manifest.json").read_text())
    ft = m["float_tolerance"]
    v = read_vectors(b.path)
    assert ft["tolerance"] == float_tolerance(model, v.inputs)["tolerance"] == recorded_tolerance(m)
    assert "max(1, |torch logit|)" in ft["rule"] and "gamma_n" in ft["derivation"]
    assert m["onnx"]["checked_with"] == "float_tolerance" and "tolerance" not in m["onnx"]
    assert m["onnx"]["max_scaled_diff_vs_torch"] <= ft["tolerance"]
    # not vacuous: below 1e-3 of the logits' scale, and the tanh approximation of GELU (an easy slip in a port)
    # is outside it
    assert ft["tolerance"] < 1e-3
    with torch.no_grad():
        x = torch.from_numpy(v.inputs)
        for lin, norm in zip(model.linears, model.norms):
            x = F.gelu(norm(lin(x)), approximate="tanh")
        tanh = model.head(x).numpy()
    assert excess(tanh, v.torch_logits) > ft["tolerance"]


def test_check_bundle_refuses_a_loosened_tolerance(exported, tmp_path):
    import shutil

    _, b = exported
    copy_ = tmp_path / "b"
    shutil.copytree(b.path, copy_)
    lines = check_bundle(copy_)
    assert any("float tolerance" in line and "error bound" in line for line in lines), lines
    m = json.loads((copy_ / "manifest.json").read_text())
    m["float_tolerance"]["tolerance"] = 0.5
    (copy_ / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(ValueError, match="float_tolerance 0.5 is not the float32 bound"):
        check_bundle(copy_)


def test_a_bundle_older_than_the_bound_keeps_its_recorded_tolerance():
    """The committed example bundle records onnx.tolerance 1e-5 (before the bound): its checks read that."""
    m = json.loads((EXAMPLE / "manifest.json").read_text())
    assert "float_tolerance" not in m and recorded_tolerance(m) == 1e-5
    lines = check_bundle(EXAMPLE)
    assert any("older than the float32 bound" in line for line in lines), lines


def _failing_tolerance(monkeypatch):
    """Make the ONNX check fail for real: a tolerance no float32 evaluation meets."""
    real = f32_bound.float_tolerance
    monkeypatch.setattr(f32_bound, "float_tolerance", lambda m, x: {**real(m, x), "tolerance": 1e-30})


def test_a_failed_export_leaves_no_half_written_bundle(tmp_path, monkeypatch):
    """The ONNX check fails after the headers, model.img and vectors were written: nothing of them is left, the
    folder is not created, no temporary folder stays behind, and an existing bundle in `out` is untouched."""
    model = quick_model("24,9")
    x = draw_inputs(1000, None, seed=3)
    _failing_tolerance(monkeypatch)
    with pytest.raises(ValueError, match=r"onnxruntime logits differ from torch") as info:
        export_bundle(model, tmp_path / "new", inputs=x)
    assert str(tmp_path / "new" / "model.onnx") in str(info.value) and ".partial-" not in str(info.value)
    assert not (tmp_path / "new").exists()
    assert [p.name for p in tmp_path.iterdir()] == []

    monkeypatch.undo()
    old = export_bundle(quick_model("sn-s"), tmp_path / "old", inputs=x)
    (tmp_path / "old" / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in (tmp_path / "old").iterdir()}
    _failing_tolerance(monkeypatch)
    with pytest.raises(ValueError):
        export_bundle(model, tmp_path / "old", inputs=x)
    assert {p.name: p.read_bytes() for p in (tmp_path / "old").iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]
    monkeypatch.undo()
    check_bundle(old.path)


def test_the_error_line_is_not_overwritten_by_the_progress_bar(tmp_path, monkeypatch):
    """`fleetlab export` failing inside the export: the bar is cleared before the error is printed, so the last
    thing on the terminal line (after the last carriage return) is the whole error line."""
    from fleetlab.cli import main

    model_path = save_model(tmp_path / "m.pt", build("24,9", seed=1))
    _failing_tolerance(monkeypatch)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["export", str(model_path), "--out", str(tmp_path / "b"), "--builtin-vectors"])
    assert code == 1
    text = err.getvalue()
    assert "export" in text.split("fleetlab export: error:")[0]  # the bar was drawn before the error
    last = text.split("\r")[-1]
    assert last.startswith("fleetlab export: error:"), repr(text[-400:])
    assert "onnxruntime logits differ from torch" in last
    assert not (tmp_path / "b").exists()
