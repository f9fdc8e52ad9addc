"""Write, load and check an export bundle (one directory per model).

Files: model.onnx, slipest_model_f32.h, slipest_model_q.h, vectors.npz, vectors.bin,
accuracy.json/.md (when data was given) and manifest.json, which records the sha256 of every
other file and the content hash embedded in both headers. `load_bundle` refuses a bundle whose
files were truncated or edited, or whose headers disagree with the manifest.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from fleetlab.data.contracts import CLASS_NAMES, FEATURE_NAMES
from fleetlab.data.features_int import FEATURE_LSB, quantize_features
from fleetlab.models.mlp import arch_of

from . import f32_bound, headers, manifest, model_image, onnx_export, vectors
from . import sns_profile
from .quant import FloatNet, QNet, quantize
from fleetlab.errors import InputError

ONNX_FILE = "model.onnx"
# Every file a bundle can hold; an export removes the ones it does not rewrite (never other files).
BUNDLE_FILES = (ONNX_FILE, "slipest_model_f32.h", "slipest_model_q.h", "model.img", "vectors.npz", "vectors.bin",
                "accuracy.json", "accuracy.md", "manifest.json")
ROUNDING = {
    "rsr": "rsr(x,k) = floor((x + 2^(k-1)) / 2^k) for k >= 1, x for k = 0 (round half up)",
    "parameters": "round half away from zero (float64) at export",
    "features": "round half away from zero of x / LSB, saturated to int16 (counted)",
    "argmax": "first maximum (ties to the lowest class)",
    "saturation": "u (GELU input) saturates to int16, eps is capped at 2^30; each event counts one saturation",
}


def _image_entry(qn: QNet, hmac_key: bytes | None) -> dict:
    """manifest.json `model_image`: format 1 for an SN-S, format 2 (the layer table) for any other."""
    layout = model_image.layout.layout_for(qn.hidden)
    return {"file": model_image.IMAGE_FILE, "format_version": layout.version, "arch_id": layout.arch,
            "byte_order": "little-endian", "hmac_sha256": hmac_key is not None}


def _quantization_entry(qn: QNet) -> dict:
    """manifest.json `quantization`: the scheme's scalars, the roundings and, for an SN-S, where each array of
    its flat header comes from."""
    entry = {**manifest.quantization_scalars(qn), "rounding": ROUNDING}
    if sns_profile.fits(qn):
        flat = sns_profile.q_arrays(qn)
        entry["arrays"] = {headers.Q_MEMBERS[attr]: {"from": attr, "ctype": ctype, "shape": list(np.shape(flat[attr]))}
                           for attr, ctype, _, _ in headers.Q_ARRAYS}
    return entry


@dataclass
class Bundle:
    path: Path
    manifest: dict[str, Any]
    fparams: FloatNet | None  # None: an ONNX-only bundle
    qparams: QNet | None

    @property
    def content_hash(self) -> str:
        return self.manifest["content_hash"]


def _json_safe(meta: dict) -> dict:
    return json.loads(json.dumps(meta, default=str))


def _versions() -> dict[str, str]:
    import onnx
    import onnxruntime

    from fleetlab import __version__

    return {
        "fleetlab": __version__, "torch": torch.__version__, "onnx": onnx.__version__,
        "onnxruntime": onnxruntime.__version__, "numpy": np.__version__, "python": platform.python_version(),
    }


def _flat_hash(model: torch.nn.Module) -> str:
    h = hashlib.sha256(manifest.CONTENT_TAG + b"onnx-only\n")
    for p in model.parameters():
        h.update(p.detach().numpy().astype("<f4").tobytes())
    return h.hexdigest()


def export_bundle(
    model: torch.nn.Module,
    out: Path,
    *,
    inputs: np.ndarray,
    meta: dict | None = None,
    model_path: Path | None = None,
    data_dirs: list[Path] | None = None,
    onnx_only: bool = False,
    vector_sources: dict | None = None,
    c_name: str = headers.DEFAULT_C_NAME,
    model_version: int = 1,
    hmac_key: bytes | None = None,
    progress: bool = True,
) -> Bundle:
    """Export `model` into directory `out` (created; existing bundle files are replaced, other files kept). With
    hmac_key, model.img carries an HMAC-SHA256 tag (for a flight build provisioned with the same key).

    The files are written into a temporary folder beside `out` and moved into `out` only when every step and
    check passed, so a failed export leaves no half-written bundle (and a bundle already in `out` untouched)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out}: exists and is not a folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    steps = tqdm(total=5, desc="export", leave=False, disable=not progress)
    try:
        m, fp, qp = _write_bundle(model, work, steps, inputs=inputs, meta=meta, model_path=model_path,
                                  data_dirs=data_dirs, onnx_only=onnx_only, vector_sources=vector_sources,
                                  c_name=c_name, model_version=model_version, hmac_key=hmac_key)
        _install(work, out)
    except (ValueError, OSError) as e:
        try:  # the message names the bundle, not the temporary folder
            renamed = type(e)(str(e).replace(str(work), str(out))) if str(work) in str(e) else None
        except TypeError:  # an error type that takes other arguments: its own message, then
            renamed = None
        if renamed is None:
            raise
        raise renamed from None
    finally:
        steps.close()  # before the caller prints an error: a bar cleared after it would blank that line
        shutil.rmtree(work, ignore_errors=True)
    return Bundle(out, m, fp, qp)


def _install(work: Path, out: Path) -> None:
    """Move the finished bundle files from `work` into `out`: the old manifest goes first and the new one comes
    last, so that a folder caught in between holds no manifest (load_bundle refuses it) rather than a wrong one."""
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out}: exists and is not a folder")
    out.mkdir(exist_ok=True)
    (out / manifest.MANIFEST).unlink(missing_ok=True)
    for name in BUNDLE_FILES:
        (out / name).unlink(missing_ok=True)
    for f in sorted(work.iterdir(), key=lambda p: p.name == manifest.MANIFEST):
        os.replace(f, out / f.name)


def _write_bundle(model: torch.nn.Module, out: Path, steps, *, inputs: np.ndarray, meta: dict | None,
                  model_path: Path | None, data_dirs: list[Path] | None, onnx_only: bool, vector_sources: dict | None,
                  c_name: str, model_version: int, hmac_key: bytes | None) -> tuple[dict, Any, Any]:
    """Every bundle file written into the (empty) folder `out`; returns the manifest and the float and
    fixed-point parameters (None, None for an ONNX-only bundle)."""
    arch = arch_of(model)
    model.eval()
    names = [ONNX_FILE]
    opset = onnx_export.export_onnx(model, out / ONNX_FILE)
    steps.update()

    fp = qp = None
    if onnx_only:
        x = np.asarray(inputs, np.float32)
        with torch.no_grad():
            tl = model(torch.from_numpy(x)).numpy()
        ftol = f32_bound.float_tolerance(model, x)
        onnx_diff, onnx_excess = onnx_export.check_onnx(out / ONNX_FILE, x, tl, ftol["tolerance"])
        content = _flat_hash(model)
        vec_info = None
    else:
        # an SN-S gets its flat headers and a format-1 image, any other network the layer-table headers and a
        # format-2 image: the writers pick the format from the network's widths
        fp = FloatNet.from_model(model)
        qp = quantize(fp)
        content = manifest.content_hash(qp, fp)
        names += [p.name for p in headers.write_headers(out, qp, fp, content, c_name, model_version)]
        names.append(model_image.write_image(out, qp, fp, content, model_version, hmac_key).name)
        steps.update()
    if not onnx_only:
        v = vectors.make_vectors(model, qp, inputs)
        names += [p.name for p in vectors.write_vectors(out, v)]
        ftol = f32_bound.float_tolerance(model, v.inputs)
        onnx_diff, onnx_excess = onnx_export.check_onnx(out / ONNX_FILE, v.inputs, v.torch_logits, ftol["tolerance"])
        steps.update()
        vec_info = {
            "n": len(v), "npz": "vectors.npz", "bin": vectors.bin_layout(len(v)),
            "sources": vector_sources or {}, "input_saturations": v.input_saturations,
            "q_saturations": int(v.q_saturations.sum()),
            "class_agreement": float(np.mean(v.q_class == v.f_class)),
        }
        if data_dirs:
            from . import accuracy

            rep = accuracy.report(model, qp, list(data_dirs))
            names += [p.name for p in accuracy.write_report(out, rep)]
    steps.update()

    m = {
        "format": manifest.FORMAT,
        "arch": arch,
        "source_model": {
            "path": str(model_path) if model_path else None,
            "sha256": manifest.file_sha256(model_path) if model_path else None,
            "meta": _json_safe(meta or {}),
        },
        "feature_names": list(FEATURE_NAMES),
        "feature_lsb": [float(v) for v in FEATURE_LSB],
        "class_names": list(CLASS_NAMES),
        "onnx": {
            "file": ONNX_FILE, "opset": opset, "input": onnx_export.INPUT_NAME, "output": onnx_export.OUTPUT_NAME,
            "dynamic_batch": True, "max_abs_diff_vs_torch": onnx_diff, "max_scaled_diff_vs_torch": onnx_excess,
            "checked_with": "float_tolerance",
        },
        # the one tolerance of every float check (ONNX, the C float path, the Python checks): export/f32_bound.py
        "float_tolerance": ftol,
        "versions": _versions(),
        "content_hash": content,
        "content_hash32": f"0x{content[:8]}",
    }
    if qp is not None:
        m["quantization"] = _quantization_entry(qp)
        m["headers"] = {"fixed_point": headers.Q_HEADER, "float": headers.F32_HEADER,
                        "model_q": f"slipest_{c_name}_q", "model_f32": f"slipest_{c_name}_f32"}
        if not sns_profile.fits(qp):
            m["headers"]["layer_table"] = True
        m["model_version"] = int(model_version)
        m["model_image"] = _image_entry(qp, hmac_key)
        m["vectors"] = vec_info
    m["files"] = manifest.file_entries(out, names)
    manifest.write_manifest(out, m)
    steps.update()
    return m, fp, qp


def load_bundle(path: Path | str) -> Bundle:
    """Load a bundle, refusing missing, truncated or edited files and inconsistent hashes."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: not a bundle directory")
    m = manifest.read_manifest(path)
    manifest.verify_files(path, m)
    if "quantization" not in m:  # ONNX-only bundle
        return Bundle(path, m, None, None)
    qfile, ffile = path / headers.Q_HEADER, path / headers.F32_HEADER
    for f in (qfile, ffile):
        if f.name not in m["files"]:
            raise InputError(f"{path / manifest.MANIFEST}: does not list {f.name}")
    net, qhash, qhash32 = headers.read_q_header(qfile)
    fn, fhash, fhash32 = headers.read_f32_header(ffile)
    msc = m["quantization"]
    _restore_scales(net, msc, qfile)
    net.check_bounds()
    for key, value in manifest.quantization_scalars(net).items():
        if msc.get(key) != value:
            raise InputError(f"{qfile}: {key} = {value}, manifest.json says {msc.get(key)}")
    _check_hashes(path, m, manifest.content_hash(net, fn), ((qfile, qhash, qhash32), (ffile, fhash, fhash32)))
    return Bundle(path, m, fn, net)


def _restore_scales(net: QNet, msc: dict, qfile: Path) -> None:
    """Set the scales s, information the headers do not carry, from the manifest's `quantization` (an SN-S's
    flat s1 and s2, any other network's per block and s_out)."""
    recorded = msc.get("hidden", [msc.get("n_hidden")])
    if list(net.hidden) != recorded or (not sns_profile.fits(net) and len(msc.get("blocks", [])) != len(net.blocks)):
        raise InputError(f"{qfile}: hidden blocks {list(net.hidden)}, manifest.json says {recorded}")
    if sns_profile.fits(net):
        scales, s_out = [msc["s1"]], msc["s2"]
    else:
        scales, s_out = [entry["s"] for entry in msc["blocks"]], msc["s_out"]
    for blk, s in zip(net.blocks, scales):
        blk.s = float(s)
    net.s_out = float(s_out)


def _check_hashes(path: Path, m: dict, content: str, named: tuple) -> None:
    """Both headers name the manifest's content hash, and their parameters hash to it."""
    for where, h, h32 in named:
        if h != m["content_hash"] or h32 != manifest.hash32(h):
            raise InputError(f"{where}: model hash {h[:16]}... disagrees with manifest.json {m['content_hash'][:16]}...")
    if content != m["content_hash"]:
        raise InputError(f"{path}: parameters in the headers hash to {content[:16]}..., manifest.json says {m['content_hash'][:16]}...")


def _check_tolerance(b: Bundle, model: torch.nn.Module, inputs: np.ndarray, tol: float) -> str:
    """The recorded float tolerance is the bound export/f32_bound.py computes for the bundle's network and vectors
    (recomputed here: a hand-edited manifest cannot loosen the float checks). A bundle written before the bound
    keeps the 1e-5 it recorded."""
    bound = f32_bound.float_tolerance(model, inputs)["tolerance"]
    if "float_tolerance" not in b.manifest:
        return (f"float tolerance {tol:.2e} recorded by a bundle older than the float32 bound "
                f"(the bound for this network and its vectors: {bound:.2e})")
    # the same 3 significant digits, rounded up; a last float64 bit of another machine may move it by one step
    if not bound / 1.01 <= tol <= bound * 1.01:
        raise InputError(f"{b.path / manifest.MANIFEST}: float_tolerance {tol:.6g} is not the float32 bound of this "
                         f"network on its vectors ({bound:.6g})")
    return f"float tolerance {tol:.2e} x max(1, |logit|) = the float32 error bound of this network on its vectors"


def check_bundle(path: Path | str, model: torch.nn.Module | None = None) -> list[str]:
    """Re-run every check of a bundle; return one line per passed check, raise ValueError on failure."""
    from .intref import argmax_lowest, run

    b = load_bundle(path)
    done = [f"files and hashes verified (content hash {b.content_hash[:16]}...)"]
    if b.qparams is None:
        return done + ["ONNX-only bundle: no fixed-point checks"]
    v = vectors.read_vectors(b.path)
    onnx_file = b.path / ONNX_FILE
    ref_model = b.fparams.to_model()
    tol = f32_bound.recorded_tolerance(b.manifest)
    done.append(_check_tolerance(b, ref_model, v.inputs, tol))
    with torch.no_grad():
        tl = ref_model(torch.from_numpy(v.inputs)).numpy()
        if model is not None:
            tl_given = model.eval()(torch.from_numpy(v.inputs)).numpy()
            if not f32_bound.excess(tl_given, tl) <= tol:
                raise InputError(f"{b.path}: the given model is not the model in this bundle")
    if not f32_bound.excess(tl, v.torch_logits) <= tol:
        raise InputError(f"{b.path}: torch_logits in vectors.npz do not match the float header parameters")
    diff, scaled = onnx_export.check_onnx(onnx_file, v.inputs, v.torch_logits, tol)
    done.append(f"ONNX: checker passed, onnxruntime vs torch max |diff| {diff:.2e} on {len(v)} vectors "
                f"({scaled:.2e} x max(1, |logit|), tolerance {tol:.2e})")
    if not np.array_equal(quantize_features(v.inputs), v.q_inputs):
        raise InputError(f"{b.path}: q_inputs in vectors.npz are not quantize_features(inputs)")
    ql, sat = run(b.qparams, v.q_inputs)
    bad = np.flatnonzero((ql != v.q_logits).any(axis=1) | (sat != v.q_saturations))
    if len(bad):
        raise InputError(f"{b.path}: integer reference differs from q_logits/q_saturations at {len(bad)} rows (first {bad[0]})")
    if not (np.array_equal(argmax_lowest(ql), v.q_class) and np.array_equal(argmax_lowest(v.torch_logits), v.f_class)):
        raise InputError(f"{b.path}: q_class/f_class in vectors.npz are not the argmax of the logits")
    binv = vectors.read_vectors_bin(b.path / "vectors.bin")
    for name, arr in v.arrays().items():
        if not np.array_equal(binv[name], arr):
            raise InputError(f"{b.path / 'vectors.bin'}: array {name} differs from vectors.npz")
    done.append(f"integer reference reproduces q_logits bit for bit on {len(v)} vectors; vectors.bin == vectors.npz")
    done.append(f"fixed-point vs float class agreement on the vectors: {np.mean(v.q_class == v.f_class):.4%}")
    if model_image.IMAGE_FILE in b.manifest["files"]:
        img = model_image.read_image((b.path / model_image.IMAGE_FILE).read_bytes())
        if img.content_hash != b.content_hash or not model_image.same_model(img, b.qparams):
            raise InputError(f"{b.path / model_image.IMAGE_FILE}: parameters or hash differ from the headers")
        done.append(f"model.img (format {img.format_version}, model version {img.model_version}) holds "
                    "the headers' parameters")
    return done
