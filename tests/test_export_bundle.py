"""`fleetlab export` end to end: bundle contents, ONNX parity, manifest/header agreement, tamper detection."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from fleetlab.data.features_int import FEATURE_LSB, quantize_features
from fleetlab.export import headers, manifest, sns_profile
from fleetlab.export.bundle import check_bundle, load_bundle
from fleetlab.export.onnx_export import onnx_logits
from fleetlab.export.quant import FloatNet, quantize
from fleetlab.export.vectors import read_vectors, read_vectors_bin
from fleetlab.models import build, save_model

from small_models import small_model


class Result:
    def __init__(self, returncode: int, stdout: str, stderr: str):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


def fleetlab(*args: str) -> Result:
    """The real CLI entry point, in process (a subprocess per call would re-import torch)."""
    import contextlib
    import io

    from fleetlab.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return Result(code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="module")
def exported(tmp_path_factory, real_data_dir) -> tuple[Path, Path]:
    """(model file, bundle dir) from the real CLI with --check and --data (real files, tmp only)."""
    tmp = tmp_path_factory.mktemp("export")
    model_path = save_model(tmp / "m.pt", small_model(), {"note": "test"})
    res = fleetlab("export", str(model_path), "--out", str(tmp / "b"), "--check", "--data", str(real_data_dir))
    assert res.returncode == 0, res.stderr
    assert "integer reference reproduces q_logits bit for bit" in res.stdout
    return model_path, tmp / "b"


def test_bundle_files_and_check_only(exported) -> None:
    _, b = exported
    for name in ("model.onnx", "slipest_model_f32.h", "slipest_model_q.h", "manifest.json", "vectors.npz",
                 "vectors.bin", "accuracy.md", "accuracy.json"):
        assert (b / name).is_file(), name
    res = fleetlab("export", "--check-only", str(b))
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("ok ") >= 3


def test_vectors_content(exported) -> None:
    _, b = exported
    v = read_vectors(b)
    assert len(v) >= 1000
    assert np.array_equal(v.q_inputs, quantize_features(v.inputs))
    q = v.q_inputs.astype(np.int32)
    for j in range(12):  # each feature reaches both int16 extremes (edge cases)
        assert q[:, j].max() == 32767 and q[:, j].min() == -32768
    assert (q == 0).all(axis=1).any()
    assert (np.abs(v.inputs / FEATURE_LSB) > 32768).any()  # rows that saturate on quantisation
    binv = read_vectors_bin(b / "vectors.bin")
    for name, arr in v.arrays().items():
        assert np.array_equal(binv[name], arr), name
    layout = json.loads((b / "manifest.json").read_text())["vectors"]["bin"]
    assert layout["total_bytes"] == (b / "vectors.bin").stat().st_size


def test_onnx_parity_dynamic_batch(exported) -> None:
    model_path, b = exported
    from fleetlab.models import load_model

    from fleetlab.export.f32_bound import excess, recorded_tolerance

    model, _ = load_model(model_path)
    v = read_vectors(b)
    m = json.loads((b / "manifest.json").read_text())
    for rows in (slice(0, 1), slice(0, 7), slice(None)):  # the bundle's float tolerance, rule and all
        x = v.inputs[rows]
        with torch.no_grad():
            ref = model(torch.from_numpy(x)).numpy()
        assert excess(onnx_logits(b / "model.onnx", x), ref) <= recorded_tolerance(m)
    assert m["onnx"]["opset"] >= 17 and m["versions"]["torch"] == torch.__version__


def test_manifest_and_headers_agree(exported) -> None:
    model_path, b = exported
    from fleetlab.models import load_model

    m = json.loads((b / "manifest.json").read_text())
    qnet, qhash, qhash32 = headers.read_q_header(b / "slipest_model_q.h")
    fnet, fhash, fhash32 = headers.read_f32_header(b / "slipest_model_f32.h")
    assert qhash == fhash == m["content_hash"]
    assert qhash32 == fhash32 == int(m["content_hash32"], 16) == int(m["content_hash"][:8], 16)
    qarr, farr = sns_profile.q_arrays(qnet), sns_profile.f32_arrays(fnet)
    for key, value in sns_profile.scalars(qnet).items():
        if key not in ("s1", "s2", "logit_scale"):  # the scales are the manifest's alone
            assert m["quantization"][key] == value, key
    for attr, ctype, _, _ in headers.Q_ARRAYS:
        assert list(qarr[attr].shape) == m["quantization"]["arrays"][headers.Q_MEMBERS[attr]]["shape"]
    # the headers hold exactly what quantize() makes of the model, and its exact float32 weights
    model, _ = load_model(model_path)
    fp = FloatNet.from_model(model)
    qp = quantize(fp)
    for name, arr in sns_profile.q_arrays(qp).items():
        assert np.array_equal(qarr[name], arr), name
    for name, arr in sns_profile.f32_arrays(fp).items():
        assert np.array_equal(farr[name], arr), name
    assert fnet.eps == np.float32(1e-5)
    assert m["content_hash"] == manifest.content_hash(qp, fp)
    assert m["quantization"]["fy"] == qp.blocks[0].fy and m["quantization"]["logit_scale"] == qp.logit_scale
    # the header defines one const model struct named after the bundle, over arrays sized by the public API
    text = (b / "slipest_model_q.h").read_text()
    assert "static const slipest_model_q_t slipest_main_q = {" in text and ".n_hidden = 30," in text
    assert "static const int16_t slipest_main_q_w1[SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES]" in text
    assert "#define SLIPEST_Q_" not in text  # every scale and shift is a struct member, none a macro
    assert m["feature_names"][0] == "feat_w_vel_mean" and len(m["feature_lsb"]) == 12


def test_accuracy_report(exported) -> None:
    _, b = exported
    rep = json.loads((b / "accuracy.json").read_text())
    entry = rep["datasets"][0]
    assert entry["all"]["n"] == 7357
    assert set(entry["roles"]) >= {"earth", "target"}
    assert 0.9 <= entry["all"]["agreement"] <= 1.0
    assert "agreement" in (b / "accuracy.md").read_text()


def _copy(b: Path, tmp: Path) -> Path:
    dst = tmp / "copy"
    shutil.copytree(b, dst)
    return dst


def test_truncated_bundle_is_refused(exported, tmp_path) -> None:
    _, b = exported
    c = _copy(b, tmp_path)
    data = (c / "slipest_model_q.h").read_bytes()
    (c / "slipest_model_q.h").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated or edited"):
        load_bundle(c)
    res = fleetlab("export", "--check-only", str(c))
    assert res.returncode == 1 and "slipest_model_q.h" in res.stderr and "Traceback" not in res.stderr


def test_edited_bundle_is_refused(exported, tmp_path) -> None:
    _, b = exported
    c = _copy(b, tmp_path)
    q = c / "slipest_model_q.h"
    text = q.read_text()
    m = re.search(r"(slipest_main_q_w1\[[^\]]*\] = \{\s*)(-?\d+)", text)
    new = str(int(m[2]) + 1 if int(m[2]) < 9 else int(m[2]) - 1)
    assert len(new) == len(m[2])  # same size: only the hash can tell
    q.write_text(text[: m.start(2)] + new + text[m.end(2):])
    with pytest.raises(ValueError, match="sha256 differs"):
        load_bundle(c)
    # even with the file entry re-hashed, the parameters no longer hash to the content hash
    man = json.loads((c / "manifest.json").read_text())
    man["files"]["slipest_model_q.h"]["sha256"] = manifest.file_sha256(q)
    (c / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ValueError, match="hash to"):
        load_bundle(c)


def test_edited_vectors_fail_the_check(exported, tmp_path) -> None:
    _, b = exported
    c = _copy(b, tmp_path)
    v = read_vectors(c)
    arrays = v.arrays()
    arrays["q_logits"] = arrays["q_logits"].copy()
    arrays["q_logits"][3, 1] += 1
    with open(c / "vectors.npz", "wb") as f:
        np.savez(f, **arrays)
    man = json.loads((c / "manifest.json").read_text())
    man["files"]["vectors.npz"] = {"sha256": manifest.file_sha256(c / "vectors.npz"), "bytes": (c / "vectors.npz").stat().st_size}
    (c / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ValueError, match="differs from q_logits"):
        check_bundle(c)


def test_sn_d_exports_the_whole_bundle_from_the_cli(tmp_path) -> None:
    """Issue 28: an SN-D goes to the C path too (layer-table headers, a format-2 model.img, vectors,
    manifest), and the check reads the image back; --onnx-only still writes ONNX alone."""
    p = save_model(tmp_path / "d.pt", build("sn-d", seed=0))
    res = fleetlab("export", str(p), "--out", str(tmp_path / "bd"), "--builtin-vectors", "--check")
    assert res.returncode == 0, res.stderr
    assert "bit for bit" in res.stdout and "model.img (format 2" in res.stdout
    for name in ("model.onnx", "slipest_model_q.h", "slipest_model_f32.h", "model.img", "vectors.bin",
                 "manifest.json"):
        assert (tmp_path / "bd" / name).is_file(), name
    res = fleetlab("export", str(p), "--out", str(tmp_path / "bo"), "--onnx-only", "--check")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "bo" / "model.onnx").is_file() and not (tmp_path / "bo" / "slipest_model_q.h").exists()


def test_bad_model_file_gives_one_line_error(tmp_path) -> None:
    """Through the installed console entry point, as a user runs it."""
    bad = tmp_path / "x.pt"
    bad.write_bytes(b"not a model")
    res = subprocess.run([sys.executable, "-m", "fleetlab.cli", "export", str(bad), "--out", str(tmp_path / "b")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 1 and "x.pt" in res.stderr and "Traceback" not in res.stderr
    assert res.stderr.startswith("fleetlab export: error: ")


def test_c_float_literals_round_trip() -> None:
    for v in (3.0, -0.0, 1e-5, 0.1, -123456.789, 3.4e38, 1.17549435e-38):
        s = headers.c_float(v)
        assert s.endswith("f") and ("." in s or "e" in s)
        assert np.float32(float(s[:-1])) == np.float32(v)
    with pytest.raises(ValueError):
        headers.c_float(float("nan"))


@pytest.mark.parametrize("hidden, flat", [((30,), True), ((24,), False), ((24, 9), False)])
def test_one_header_writer_and_reader_for_every_network(hidden, flat, tmp_path) -> None:
    """One writer and one reader serve every network: an SN-S (one block of 30) gets the flat struct of the
    small-flash kernel, any other network (one block of another width included) the layer table, and both read
    back as the same network."""
    from fleetlab.models.mlp import SlipNet

    torch.manual_seed(1)
    fn = FloatNet.from_model(SlipNet(hidden).eval())
    qn = quantize(fn)
    assert sns_profile.fits(qn) is flat
    h = manifest.content_hash(qn, fn)
    paths = headers.write_headers(tmp_path, qn, fn, h)
    assert [p.name for p in paths] == [headers.F32_HEADER, headers.Q_HEADER]
    text = (tmp_path / headers.Q_HEADER).read_text()
    assert (".n_hidden = 30," in text) is flat and ("slipest_main_q_layers[" in text) is not flat
    got, gh, gh32 = headers.read_q_header(tmp_path / headers.Q_HEADER)
    gf, fh, fh32 = headers.read_f32_header(tmp_path / headers.F32_HEADER)
    assert gh == fh == h and gh32 == fh32 == manifest.hash32(h)
    assert got.hidden == gf.hidden == hidden
    for a, b in zip(got.blocks, qn.blocks):
        assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("w", "b", "g", "bb", "gelu"))
        assert (a.fg, a.fy, a.eps_m, a.eps_e) == (b.fg, b.fy, b.eps_m, b.eps_e)
    assert all(np.array_equal(getattr(got, k), getattr(qn, k)) for k in ("w_out", "b_out", "rsqrt_seed"))
    for a, b in zip(gf.blocks, fn.blocks):
        assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("w", "b", "gamma", "beta"))
    assert np.array_equal(gf.w_out, fn.w_out) and np.array_equal(gf.b_out, fn.b_out) and gf.eps == np.float32(fn.eps)


def test_sn_s_header_members_must_be_the_schemes(tmp_path) -> None:
    """A flat SN-S header whose shifts are not those the scheme gives its width is refused by name."""
    fn = FloatNet.from_model(build("sn-s", seed=2))
    qn = quantize(fn)
    headers.write_headers(tmp_path, qn, fn, manifest.content_hash(qn, fn))
    q = tmp_path / headers.Q_HEADER
    q.write_text(q.read_text().replace(".h_bits = 24,", ".h_bits = 23,"))
    with pytest.raises(ValueError, match=r"\.h_bits = 23, the scheme gives 24"):
        headers.read_q_header(q)


def test_committed_example_bundle_is_current() -> None:
    """The example bundle in the repo passes every check with today's code and came from simulator data."""
    example = Path(__file__).resolve().parents[1] / "firmware_c" / "bundles" / "example"
    lines = check_bundle(example)
    assert any("bit for bit" in line for line in lines)
    m = json.loads((example / "manifest.json").read_text())
    assert "fleetlab simulate" in m["source_model"]["meta"]["trained_on"]
    assert m["vectors"]["n"] >= 1000
    assert sum(e["bytes"] for e in m["files"].values()) < 1_000_000
