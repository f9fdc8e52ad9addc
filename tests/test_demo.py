"""`fleetlab demo --quick`: the whole pipeline, as the README's main job runs it."""

import json
import subprocess
import sys

import pytest

from fleetlab.data.dataset import load_dataset


def test_demo_quick_end_to_end(tmp_path):
    out = tmp_path / "demo"
    r = subprocess.run([sys.executable, "-m", "fleetlab.cli", "demo", "--quick", "--out", str(out)],
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = (out / "report.md").read_text()
    assert "**All stages green**" in report and "FAILED" not in report
    for stage in ("Simulate", "AcoMerge", "MCCV", "Export", "host", "Cortex-M4", "SLCAN", "cost"):
        assert stage in report, stage
    # the label-noise stage: its table (how many labels were corrupted) and plot
    assert "## Calibration labels with noise" in report and "| labels corrupted | 0.0 % |" in report
    assert (out / "noise" / "sweep.png").is_file()
    # the assurance stage's own summary table, for the bundle this run exported
    assert "## Assurance evidence" in report and "MISRA C:2012 (cppcheck addon)" in report
    assert (out / "assurance" / "assurance.html").exists()
    assert "Frama-C EVA skipped (--no-eva)" in (out / "assurance" / "assurance.md").read_text()  # quick: no EVA
    # the report's figures are the run's own files
    manifest = json.loads((out / "bundle" / "manifest.json").read_text())
    assert manifest["content_hash"] in report
    emu = json.loads((out / "emulate.json").read_text())
    assert emu["mismatches"] == 0 and emu["windows"] > 0 and emu["bit_exact"] == emu["windows"]
    assert f"| {emu['windows']} | {emu['bit_exact']} | 0 |" in report
    # after landing: the fused model replaced the Earth-analog one over CANopen, bit-exact, no window lost
    landing = json.loads((out / "after_landing.json").read_text())
    assert landing["boot_model_bit_exact"] and landing["new_model_bit_exact"] and landing["after"]["version"] == 2
    assert landing["windows_answered_during_upload_phase"] == landing["windows_streamed_during_upload_phase"]
    assert "## After landing: model update over CANopen" in report
    # SN-D beside SN-S: uploaded to the same node after the SN-S bundle, served bit-exact, its cost counted
    deep = json.loads((out / "sn_d_upload.json").read_text())
    assert deep["new_model_bit_exact"] and deep["after"]["version"] == 3
    assert deep["upload"]["image_bytes"] > landing["upload"]["image_bytes"]
    assert "## SN-S against SN-D" in report
    assert "| sn-d | " in report and f"{deep['upload']['image_bytes']:,}" in report
    _check_sn_d_cost(out)
    rows = sum(len(f.table) for f in load_dataset(out / "data").files)
    assert f"{rows} windows" in report
    assert "100% tests passed" in report
    html = (out / "report.html").read_text()
    assert "<table>" in html and "convergence.png" in html
    for png in ("features.png", "fuse/convergence.png", "fixed_vs_float.png"):
        assert (out / png).stat().st_size > 5000, png


def _check_sn_d_cost(out):
    """The demo's `fleetlab bench c --compare SN-D --json` (issue 28 item 6): for SN-D as for SN-S, instructions
    per fixed-point and float inference and per node sample, kernel + model flash, stack and RAM on the M4, and
    host C against onnxruntime; the row's RAM is the reference figure's formula."""
    line = next(x for x in (out / "logs" / "bench_c.log").read_text().splitlines() if x.startswith("{"))
    bench = json.loads(line)
    sns, snd = bench["cpu_targets"]["cortex-m4"], bench["compare"]["cpu_targets"]["cortex-m4"]
    assert bench["arch"] == "sn-s" and bench["compare"]["arch"] == "sn-d"
    keys = ("instructions_per_inference_q", "instructions_per_inference_f32", "instructions_per_sample_node_slcan",
            "flash_bytes_kernel_and_model", "stack_bytes_q", "stack_bytes_f32", "ram_bytes")
    for key in keys:
        assert sns[key] > 0 and snd[key] > 0, key
    assert sns["ram_bytes"] == bench["m4_ram_bytes"]
    # SN-D: 22x the multiply-accumulates, its weights in flash, its scratch on the stack
    assert snd["instructions_per_inference_q"] > 5 * sns["instructions_per_inference_q"]
    assert snd["flash_bytes_kernel_and_model"] > 20_000 > sns["flash_bytes_kernel_and_model"]
    assert snd["ram_bytes"] > sns["ram_bytes"]
    c = bench["compare"]
    assert c["host_ns_per_inference_q"] > 0 and c["onnxruntime_ns_per_inference"] > 0
    assert c["speedup_vs_onnxruntime"] == pytest.approx(c["onnxruntime_ns_per_inference"] / c["host_ns_per_inference_q"])
