"""`fleetlab export`: a trained model -> ONNX, float and fixed-point C headers, test vectors, manifest."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from . import options
from ..errors import InputError

DEFAULT_VECTORS = 1200


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Export a fleetlab model (.pt from training or fusion) into a bundle directory: model.onnx, "
        "slipest_model_f32.h, slipest_model_q.h (fixed point), model.img (the run-time model image), "
        "vectors.npz/.bin (inputs, torch float and integer-reference logits) and manifest.json (scheme parameters, "
        "versions, hashes). Any architecture (sn-s, sn-d, hidden sizes such as 64,32) exports; other than SN-S its "
        "headers carry a layer table and model.img is image format 2 (the layer table; SN-S keeps format 1). "
        "With --data, also writes accuracy.md/json: fixed-point vs float agreement on those windows."
    )
    p.add_argument("model", nargs="?", type=Path, help="model file written by fleetlab (save_model)")
    p.add_argument("--out", type=Path, help="bundle directory to write (created)")
    p.add_argument("--data", type=Path, action="append", default=[], metavar="DIR",
                   help="dataset folder (fleetlab simulate output or Fleet-To-Lab CSVs): vectors are drawn from "
                   "its windows and the accuracy report covers every role; may be given more than once")
    p.add_argument("--vectors", type=int, default=DEFAULT_VECTORS, metavar="N",
                   help=f"number of test vectors, edge cases included (default {DEFAULT_VECTORS}, at least 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the vector draw and of the simulator run (default 0)")
    p.add_argument("--builtin-vectors", action="store_true",
                   help="without --data, draw vectors around built-in plausible windows instead of running the "
                   "simulator (faster)")
    p.add_argument("--check", action="store_true", help="after exporting, re-run every bundle check")
    p.add_argument("--check-only", type=Path, metavar="BUNDLE",
                   help="only check an existing bundle (hashes, ONNX parity, integer reference); no export")
    p.add_argument("--model-version", type=int, default=1, metavar="N",
                   help="model version written into model.img and the C model structs (monotonically increasing "
                   "per deployment; default 1)")
    p.add_argument("--hmac-key", type=Path, metavar="FILE",
                   help="sign model.img with HMAC-SHA256 under the key in FILE (16..64 raw bytes), the key a "
                   "flight build was provisioned with (cmake -DSLIPEST_HMAC_KEY_FILE=FILE)")
    p.add_argument("--c-name", default="main", metavar="NAME",
                   help="C name of the bundle's models: slipest_NAME_q / slipest_NAME_f32 (default main); give "
                   "two bundles different names to include both in one image")
    p.add_argument("--onnx-only", action="store_true",
                   help="write model.onnx and the manifest only (no C headers, vectors or image)")
    options.no_progress(p)


def _data_windows(dirs: list[Path]) -> np.ndarray | None:
    from . import dataset_input

    xs = []
    for d in dirs:
        ds = dataset_input.load(d)
        xs += [ds.xy(role)[0] for role in ds.roles]
    return np.concatenate(xs) if xs else None


def _print_checks(lines: list[str]) -> None:
    for line in lines:
        print(f"  ok  {line}")


def run(args: argparse.Namespace) -> int:
    from fleetlab.export.bundle import check_bundle, export_bundle

    if args.check_only is not None:
        print(f"checking {args.check_only}")
        _print_checks(check_bundle(args.check_only))
        return 0
    if args.model is None or args.out is None:
        raise InputError("give MODEL and --out BUNDLE (or --check-only BUNDLE)")
    if args.vectors < 1000 and not args.onnx_only:
        raise InputError(f"--vectors {args.vectors}: at least 1000 test vectors are required")

    from ..models import load_model

    from fleetlab.export.vectors import draw_inputs, simulator_windows

    model, meta = load_model(args.model)
    windows, kind = _data_windows(args.data), "dataset windows"
    if windows is None and not (args.builtin_vectors or args.onnx_only):
        windows, kind = simulator_windows(args.seed), f"simulator windows (scenario seed {args.seed}, scale 0.05)"
    if windows is None:
        kind = "built-in plausible windows + random draws"
    inputs = draw_inputs(args.vectors, windows, args.seed)
    sources = {"data": [str(d) for d in args.data], "seed": args.seed, "kind": kind}
    b = export_bundle(model, args.out, inputs=inputs, meta=meta, model_path=args.model, data_dirs=args.data,
                      onnx_only=args.onnx_only, vector_sources=sources, c_name=args.c_name,
                      model_version=args.model_version,
                      hmac_key=args.hmac_key.read_bytes() if args.hmac_key is not None else None, progress=not args.no_progress)
    print(f"wrote {b.path} ({meta['arch']}, content hash {b.content_hash[:16]}...)")
    for name, entry in b.manifest["files"].items():
        print(f"  {name:24s} {entry['bytes']:>9d} bytes")
    if b.qparams is not None:
        q = b.manifest["quantization"]
        shifts = (" ".join(f"[{b_['width']}: FY={b_['fy']} FG={b_['fg']} FZ={b_['fz']}]" for b_ in q["blocks"])
                  if "blocks" in q else f"FY={q['fy']} FG={q['fg']} w1_max={q['w1_max']} w2_max={q['w2_max']}")
        print(f"  fixed point: {shifts} logit scale {q['logit_scale']:.6g}; "
              f"vector agreement {b.manifest['vectors']['class_agreement']:.4%}")
    acc = b.path / "accuracy.md"
    if acc.exists():
        print(acc.read_text())
    if args.check:
        print(f"checking {b.path}")
        _print_checks(check_bundle(b.path, model))
    return 0
