"""The demo report: DIR/report.md and DIR/report.html, built from the files the stages wrote.

Every number comes from a stage's output file (data info JSON, fuse report, MCCV results,
bundle manifest and accuracy report, ctest logs, emulation JSON, C benchmark JSON).
A section whose stage failed or did not run says so instead of showing numbers.
"""

from __future__ import annotations

import datetime as _dt
import json
import re
import shlex
from pathlib import Path

from . import __version__
from .data.contracts import CLASS_NAMES
from fleetlab.host_tools.firmware import targets as cpu_targets


def _img(path: Path, out: Path, alt: str) -> str:
    return f"![{alt}]({path.relative_to(out).as_posix()})" if path.exists() else f"_(no {alt} plot)_"


def _json_or_none(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def _demote(md: str, levels: int = 2) -> str:
    """Push a sub-report's headings down so they nest under the demo's sections."""
    return re.sub(r"^(#+)", lambda m: "#" * min(6, len(m.group(1)) + levels), md, flags=re.M)


def _section_data(out: Path, stage) -> list[str]:
    info = json.loads(stage.outputs["stdout"])
    lines = ["## Data", "", f"{info['total_rows']} windows (2 s each) in {len(info['files'])} traverse files "
             f"of `{Path(info['path']).name}`; rows rejected for NaN/Inf: {info['rejected_nonfinite_rows']}.", "",
             "| role | traverses | windows | " + " | ".join(CLASS_NAMES) + " |", "|---|---:|---:|---:|---:|---:|"]
    for role, r in info["roles"].items():
        n = max(r["rows"], 1)
        mix = " | ".join(f"{c} ({100 * c / n:.0f} %)" for c in r["classes"])
        lines.append(f"| {role} | {r['files']} | {r['rows']} | {mix} |")
    return lines + ["", _img(out / "features.png", out, "per-class feature histograms"), ""]


def _section_fuse(out: Path) -> list[str]:
    fuse = out / "fuse"
    return ["## Fusion (one calibration draw)", "", _demote((fuse / "report.md").read_text()).strip(), "",
            _img(fuse / "convergence.png", out, "AcoMerge convergence"), ""]


def _section_evaluate(out: Path) -> list[str]:
    ev = out / "evaluate"
    res = json.loads((ev / "results.json").read_text())
    lines = ["## Comparison by Monte Carlo cross-validation", "",
             f"{res['config']['runs']} runs, each with a fresh calibration draw (protocol `{res['config']['protocol']}`); "
             "experts trained once on the source data.", "", (ev / "table.md").read_text().strip(), ""]
    lines += [_img(p, out, p.stem.replace("_", " ")) for p in sorted(ev.glob("*.png"))]
    return lines + [""]


def _agreement_plot(acc: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [(f"{Path(d['path']).name}/{role}", s) for d in acc["datasets"] for role, s in d["roles"].items()]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 0.5 * len(rows) + 1.8))
    names = [r[0] for r in rows]
    a1.barh(names, [100 * s["agreement"] for _, s in rows], color="tab:green")
    a1.axvline(100 * acc["targets"]["agreement"], color="k", ls="--", lw=1, label="target")
    a1.set_xlim(min(99.0, min(100 * s["agreement"] for _, s in rows) - 0.5), 100.05)
    a1.set_xlabel("fixed-point vs float class agreement (%)")
    a1.legend(loc="lower left")
    y = range(len(rows))
    a2.barh([i + 0.2 for i in y], [s["bacc_float"] for _, s in rows], height=0.4, label="float")
    a2.barh([i - 0.2 for i in y], [s["bacc_fixed"] for _, s in rows], height=0.4, label="fixed point")
    a2.set_yticks(list(y), [""] * len(rows))
    a2.set_xlabel("balanced accuracy")
    a2.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _section_export(out: Path) -> list[str]:
    bundle = out / "bundle"
    man = json.loads((bundle / "manifest.json").read_text())
    lines = ["## Export bundle", "", f"Model content hash: `{man['content_hash']}` (the C library reports "
             f"`{man['content_hash32']}` at run time). ONNX opset {man['onnx']['opset']}, max |ONNX − torch| = "
             f"{man['onnx']['max_abs_diff_vs_torch']:.2e}.", "", "| file | bytes |", "|---|---:|"]
    lines += [f"| `{p.name}` | {p.stat().st_size:,} |" for p in sorted(bundle.iterdir()) if p.is_file()]
    acc = _json_or_none(bundle / "accuracy.json")
    if acc:
        lines += ["", _demote((bundle / "accuracy.md").read_text()).strip(), "",
                  _img(_agreement_plot(acc, out / "fixed_vs_float.png"), out, "fixed-point vs float agreement")]
    return lines + [""]


def _ctest_summary(log: Path) -> str:
    m = re.findall(r"^\d+% tests passed, \d+ tests failed out of \d+", log.read_text(), flags=re.M)
    return m[-1] if m else "no ctest summary in the log"


def _section_c(out: Path, by_name: dict, cortex_note: str | None) -> list[str]:
    lines = ["## C estimator builds", "", "| build | ctest |", "|---|---|"]
    lines.append(f"| host (x86-64) | {_ctest_summary(out / 'logs' / 'build_host.log')} |")
    cpu = cpu_targets.reference()  # the demo's cross build (toolchain/cli/demo.py)
    if "build_m4" in by_name:
        lines.append(f"| {cpu.label} | {_ctest_summary(out / 'logs' / 'build_m4.log')} |")
    else:
        lines.append(f"| {cpu.label} | {cortex_note} |")
    return lines + [""]


def _section_emulate(out: Path) -> list[str]:
    e = json.loads((out / "emulate.json").read_text())
    lat = e.get("latency_us", {})
    return ["## Host emulation loop (SLCAN over a pseudo-terminal)", "",
            "| windows | bit-exact | mismatches | flagged | rejected frames | dropped | latency p50 / p99 (µs) |",
            "|---:|---:|---:|---:|---:|---:|---|",
            f"| {e['windows']} | {e['bit_exact']} | {e['mismatches']} | {e['flagged_windows']} | "
            f"{e['rejected_frames']} | {e['dropped_frames']} | {lat.get('p50', 0):.0f} / {lat.get('p99', 0):.0f} |", "",
            *([f"Streamed as fast as possible: {e['frames_per_s']:,.0f} frames/s, {e['windows_per_s']:,.0f} windows/s "
               f"(a rover at 50 Hz needs {e['realtime_need']['frames_per_s']:.0f} frames/s); the latency is mostly time "
               "queued in the pseudo-terminal. Add `--realtime` to `fleetlab emulate` for the paced figure.", ""]
              if not e.get("realtime", True) and "frames_per_s" in e else [])]


def _section_after_landing(out: Path) -> list[str]:
    a = json.loads((out / "after_landing.json").read_text())
    up = a["upload"]
    return ["## After landing: model update over CANopen", "",
            "The node (the emulator, CANopen profile) boots with the Earth-analog model; the fused model, exported as "
            "version 2, goes to its inactive slot by SDO block download while telemetry keeps streaming, is validated, "
            "and is activated between two windows.", "",
            "| image (B) | SDO frames | CAN bits | bus time at 500 kbit/s | windows answered / streamed | during the upload "
            "| old model bit-exact | version | new model bit-exact (windows) |",
            "|---:|---:|---:|---:|---:|---:|---|---|---|",
            f"| {up['image_bytes']} | {up['sdo_frames']} | {up['bus_bits']} | {up['bus_time_s_at_500k'] * 1000:.1f} ms | "
            f"{a['windows_answered_during_upload_phase']} / {a['windows_streamed_during_upload_phase']} | "
            f"{up['windows_during_upload']} | {a['boot_model_bit_exact']} | {a['before']['version']} → "
            f"{a['after']['version']} ({a['after']['hash32']}) | {a['new_model_bit_exact']} "
            f"({a['windows_after_activation']}) |", "",
            "Bus time: every frame's bits on a classic CAN bus (SOF to intermission, stuff bits counted exactly, "
            "`fleetlab.host_tools.wire.can_bits`) divided by the bit rate; the emulator's pseudo-terminal itself is "
            "faster, so the windows answered while the upload ran are a wall-clock count on this host.", ""]


def _section_bench(stage) -> list[str]:
    b = json.loads(stage.outputs["stdout"])
    rows = [(k, v) for k, v in b.items() if isinstance(v, (int, float))]
    return ["## Cost and size of the C estimator", "", "| figure | value |", "|---|---:|",
            *[f"| {k} | {v:,.1f} |" if isinstance(v, float) else f"| {k} | {v:,} |" for k, v in rows], ""]


def _section_architectures(out: Path, bench_stage) -> list[str]:
    """SN-S against SN-D on the demo data: the accuracy of one calibration draw, and what each costs the
    reference CPU target and the bus (issue: pick an architecture for a CPU, docs/integrating_slipest.md)."""
    from .models.persist import load_model

    bench = json.loads(bench_stage.outputs["stdout"])
    ref = cpu_targets.reference().name
    uploads = {"sn-s": json.loads((out / "after_landing.json").read_text()),
               "sn-d": json.loads((out / "sn_d_upload.json").read_text())}
    rows = {"sn-s": (out / "fuse", bench["cpu_targets"][ref]),
            "sn-d": (out / "fuse_sn_d", bench["compare"]["cpu_targets"][ref])}
    lines = ["## SN-S against SN-D", "",
             f"The same data, seed and AcoMerge budget; accuracy from the fuse stage's single calibration draw "
             f"(test target rows), cost on {cpu_targets.reference().description} under QEMU, upload by CANopen "
             "SDO block download to the emulated node.", "",
             "| network | test balanced accuracy | test macro-F1 | instr./q inference | instr./float inference "
             "| flash kernel+model (B) | model image (B) | upload bus time at 500 kbit/s | served bit-exact after activation |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for arch, (fuse_dir, cost) in rows.items():
        test = load_model(fuse_dir / "fused.pt")[1]["test"]
        up = uploads[arch]["upload"]
        lines.append(f"| {arch} | {test['balanced_accuracy']:.4f} | {test['macro_f1']:.4f} "
                     f"| {cost['instructions_per_inference_q']:,.0f} | {cost['instructions_per_inference_f32']:,.0f} "
                     f"| {cost['flash_bytes_kernel_and_model']:,} | {up['image_bytes']:,} "
                     f"| {up['bus_time_s_at_500k'] * 1000:,.0f} ms | {uploads[arch]['new_model_bit_exact']} |")
    return lines + ["", "One draw says little about accuracy: `fleetlab evaluate --arch sn-d` gives the Monte Carlo "
                    "comparison. docs/integrating_slipest.md explains how to pick an architecture for a CPU.", ""]


def write_report(out: Path, stages: list, total_s: float, args, prof, cortex_note: str | None) -> Path:
    by_name = {s.name: s for s in stages}
    ok = all(s.ok for s in stages)
    lines = [
        "# fleetlab demo report", "",
        f"Generated {_dt.datetime.now().isoformat(timespec='seconds')} by fleetlab {__version__}: "
        f"`fleetlab demo --out {args.out}{' --quick' if args.quick else ''} --seed {args.seed}`.", "",
        f"**{'All stages green' if ok else 'Some stages FAILED'}** — total {total_s:.0f} s.", "",
        "| stage | status | time (s) | command (repeat it on your own data) |", "|---|---|---:|---|",
    ]
    for s in stages:
        status = {True: "green", False: "**FAILED**", None: "not run"}[s.ok]
        cmd = "<br>".join(f"`{_display(c)}`" for c in s.commands)
        lines.append(f"| {s.title} | {status}{(' — ' + s.note) if s.note else ''} | {s.seconds:.1f} | {cmd} |")
    lines.append("")
    sections = [
        ("data", lambda: _section_data(out, by_name["data"])),
        ("fuse", lambda: _section_fuse(out)),
        ("evaluate", lambda: _section_evaluate(out)),
        ("noise", lambda: _section_noise(out)),
        ("export", lambda: _section_export(out)),
        ("build_host", lambda: _section_c(out, by_name, cortex_note)),
        ("emulate", lambda: _section_emulate(out)),
        ("after_landing", lambda: _section_after_landing(out)),
        ("bench_c", lambda: _section_bench(by_name["bench_c"])),
        # bench_c runs after sn_d and a failed stage stops the demo, so a green bench_c has both bundles
        ("bench_c", lambda: _section_architectures(out, by_name["bench_c"])),
        ("assure", lambda: _section_assure(out)),
    ]
    for name, make in sections:
        if name not in by_name:
            lines += [f"## {name}", "", f"_not part of this run: {cortex_note}._", ""]
        elif by_name[name].ok:
            lines += make()
        else:
            lines += [f"## {name}", "", "_stage did not complete; no figures._", ""]
    md = "\n".join(lines)
    (out / "report.md").write_text(md)
    _write_html(md, out / "report.html")
    return out / "report.md"


def _section_noise(out: Path) -> list[str]:
    """The label-noise sweep of `fleetlab evaluate --label-noise-sweep` (noise/sweep.md and sweep.png)."""
    noise = out / "noise"
    return ["## Calibration labels with noise", "",
            "D_Cal's labels corrupted as visual odometry would (here a fifth moved to a neighbouring class); the "
            "test rows keep exact labels. The full sweep and the VO model: docs/paper_table.md.", "",
            _demote((noise / "sweep.md").read_text().strip()), "", _img(noise / "sweep.png", out, "balanced accuracy "
            "against the label-noise rate"), ""]


def _section_assure(out: Path) -> list[str]:
    """The summary table of the evidence report `fleetlab assure` wrote (assurance/assurance.md)."""
    text = (out / "assurance" / "assurance.md").read_text()
    summary = text.split("## Summary", 1)[1].split("\n## ", 1)[0].strip()
    return ["## Assurance evidence", "", summary, "",
            "Full report: [assurance/assurance.md](assurance/assurance.md) (and .html).", ""]


def _display(cmd: list[str]) -> str:
    """A stage command as a user types it: `python -m fleetlab.cli ...` shown as `fleetlab ...`."""
    return shlex.join(["fleetlab", *cmd[3:]] if cmd[1:3] == ["-m", "fleetlab.cli"] else cmd)


def _write_html(md: str, path: Path) -> None:
    import markdown

    body = markdown.markdown(md, extensions=["tables", "fenced_code"])
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px}"
             "img{max-width:100%}code{background:#f4f4f4}")
    path.write_text(f"<!doctype html><meta charset='utf-8'><title>fleetlab demo report</title>"
                    f"<style>{style}</style>\n{body}\n")
