"""Host emulation loop against the real C estimator: emulator process on real ptys (slcan,
COBS serial) and the C library in-process (ctypes on a python-can virtual bus)."""

from __future__ import annotations

import json
import queue
import time

import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.host_tools.verify import stream_faults as faults
from fleetlab.host_tools.verify.compare import EstimatorModel
from fleetlab.host_tools.wire.dbc import OutputAssembler, StatusReport, control_frame
from fleetlab.host_tools.emulate import DEFAULT_SCALE, emulate, soak_source
from fleetlab.host_tools.emulator import EmulatorProcess, build, default_bundle, find_artifact
from fleetlab.host_tools.binding import CEstimator
from fleetlab.host_tools.pacing import SimulatedClock
from fleetlab.host_tools.links import SlcanLink
from fleetlab.host_tools.wire.items import WireItem
from fleetlab.host_tools.sources import TelemetrySource, sim_source

JSON_KEYS = {"windows", "bit_exact", "mismatches", "flagged_windows", "rejected_frames", "dropped_frames",
             "injected_faults", "detected_faults", "latency_us"}


@pytest.fixture(scope="module")
def bundle():
    b = default_bundle()
    build(b)
    return b


@pytest.fixture(scope="module")
def sim():
    return sim_source(seed=0, scale=DEFAULT_SCALE)


def test_default_scale_gives_enough_windows(sim):
    assert sim.n_windows >= 500


@pytest.mark.parametrize("link", ["slcan", "serial", "inproc"])
def test_emulate_is_bit_exact_over_every_link(bundle, sim, link):
    res = emulate(bundle, sim, link, progress=False)
    s = res.summary()
    assert s["windows"] == sim.n_windows >= 500
    assert s["mismatches"] == 0, s["first_problems"]
    assert s["bit_exact"] == s["windows"]
    assert s["dropped_frames"] == 0 and s["rejected_frames"] == 0 and s["unexplained_windows"] == 0
    assert not s["status_problems"] and not s["host_rx_errors"]
    assert s["latency_us"]["p50"] > 0
    assert res.ok()


def test_a_fault_the_node_does_not_show_is_not_detected(bundle, sim):
    """The detector observes each fault in the node's STATUS reports: with the rejections taken out of the
    reports around them (as if the node had let the bad frames through), the counter-only faults are no
    longer detected, while the window-flag faults still are."""
    import dataclasses

    from fleetlab.host_tools import emulate as emulate_mod

    part = TelemetrySource("first 100 windows", sim.samples_q[:10_000], [])
    kinds = ["unknown_id", "duplicated_frame", "dropped_sample"]
    res = emulate(bundle, part, "inproc", kinds, 0.2, seed=4, progress=False)
    counter_only = [f for f in res.faults if not f.flags_window and f.kind != "restart"]
    assert counter_only and all(f.detected for f in res.faults)
    plan = faults.plan_telemetry(part.samples_q, kinds, 0.2, 4)  # the same plan, its faults not yet marked
    assert [f.kind for f in plan.faults] == [f.kind for f in res.faults]
    for seg in res.segments:
        seg.statuses = [dataclasses.replace(st, frames_rejected=0) for st in seg.statuses]
    emulate_mod._mark_detected(plan, res)
    assert not any(f.detected for f in plan.faults if not f.flags_window)
    assert all(f.detected for f in plan.faults if f.flags_window)


@pytest.mark.parametrize("link", ["slcan", "serial", "inproc"])
def test_injected_faults_are_all_detected(bundle, sim, link):
    kinds = faults.parse_kinds("all", link)
    part = TelemetrySource("first 300 windows", sim.samples_q[:30_000], [])  # keeps the test fast
    res = emulate(bundle, part, link, kinds, 0.05, seed=4, progress=False)
    s = res.summary()
    assert s["injected_faults"] >= 7
    assert s["detected_faults"] == s["injected_faults"], (s["faults_by_kind"], s["status_problems"])
    assert s["mismatches"] == 0 and s["mismatches_unflagged"] == 0, s["first_problems"]
    assert s["flagged_windows"] > 0 and s["rejected_frames"] > 0 and s["dropped_frames"] == 0
    assert s["restarts"] == s["faults_by_kind"].get("restart", {}).get("injected", 0)
    assert s["samples_lost_to_restart"] == 100 * s["restarts"]
    assert res.ok()


def test_emulate_cli_writes_the_json_summary(bundle, tmp_path):
    out = tmp_path / "emu.json"
    rc = fleetlab_main(["emulate", "--source", "vectors", "--link", "serial", "--inject",
                        "unknown_id,duplicated_frame,wrong_length,bad_crc,restart", "--inject-rate", "0.2",
                        "--json", str(out), "--no-progress"])
    s = json.loads(out.read_text())
    assert JSON_KEYS <= set(s) and set(s["latency_us"]) == {"p50", "p99"}
    assert rc == 0, s
    assert s["windows"] > 0 and s["mismatches"] == 0
    assert s["detected_faults"] == s["injected_faults"] > 0


def test_soak_slcan_full_speed_loses_nothing(bundle, sim):
    src = soak_source(100_000, seed=0, scale=DEFAULT_SCALE, base=sim)
    res = emulate(bundle, src, "slcan", progress=False)
    s = res.summary()
    assert s["frames_sent"] >= 100_000
    assert s["dropped_frames"] == 0 and s["mismatches"] == 0 and s["windows"] == src.n_windows
    # how fast is a benchmark figure (fleetlab bench link), not an assertion: a loaded machine is no bug


def test_model_predicts_the_c_node_counters_directly(bundle, sim):
    """Every fault plan replayed through the C node (ctypes) gives the host's predicted counters."""
    est = CEstimator(find_artifact(build(bundle), "libslipest_host.so"))
    x = sim.samples_q[: 60 * 100]
    plan = faults.plan_telemetry(x, faults.parse_kinds("all", "inproc"), 0.4, seed=11)
    for seg in plan.segments:
        est.reset()
        model = EstimatorModel()
        n_out = 0
        for i, it in enumerate(seg.items):
            model.feed(it, i)
            n_out += len(est.handle(it.frame))
        c, want = est.counters(), model.status_snapshot()
        for k in ("frames_received", "frames_rejected", "samples_dropped", "windows_flagged", "windows_done"):
            assert c[k] == getattr(want, k), k
        assert n_out >= 3 * want.windows_done


def test_emulator_answers_slcan_adapter_commands_and_counts_garbage(bundle):
    emu = EmulatorProcess(find_artifact(build(bundle), "slipest_emu"), "slcan")
    pty = emu.start()
    try:
        link = SlcanLink(pty)  # python-can sends C / S6 / O and reads the acknowledgements
        port = link.bus.serialPortOrig
        # an adapter command, an overlong line, an unknown ID, then CONTROL 2 (status now)
        port.write(b"V\r" + b"t" + b"1" * 100 + b"\r" + b"t1FF0\r")
        link.write([WireItem(control_frame(2))])
        asm, status = OutputAssembler(), None
        deadline = time.monotonic() + 5
        while status is None and time.monotonic() < deadline:  # safety net: ends on the STATUS answer
            try:
                f, _ = link.rx.get(timeout=0.1)
            except queue.Empty:
                continue
            out = asm.feed(f)
            status = out if isinstance(out, StatusReport) else None
        link.close()
        assert emu.running
    finally:
        emu.stop()
    assert status is not None
    assert (status.frames_received, status.frames_rejected, status.windows_done) == (3, 2, 0)


def test_realtime_pacing_measures_the_estimator_latency(bundle, sim):
    one = TelemetrySource("one window", sim.samples_q[:100], [])
    clock = SimulatedClock()  # the schedule on a simulated clock; the latency stays a wall-clock figure
    res = emulate(bundle, one, "serial", progress=False, realtime=True, clock=clock)
    s = res.summary()
    # the window is emitted when its last slot fills, not with the next sample: these 100 samples are all
    # there is, so a node that waited for a 101st would send no estimate at all
    assert s["windows"] == s["bit_exact"] == 1 and s["realtime"] and s["frames_sent"] == 300 + 2  # + CONTROL reset, status
    # one chunk (a sample's three frames, then CONTROL status) per 20 ms period after the leading CONTROL
    # reset: 101 waits, the clock standing at the status chunk's due time; the latency is a figure of fleetlab bench link, not an
    # assertion (its value is the machine's: under load the interpolated send time of the window's last
    # item can fall after the answer's arrival, and the figure is clamped to 0)
    (seg,) = res.segments
    assert seg.pacer.waits == 101
    assert seg.pacer.elapsed() == pytest.approx(101 / 50)
    assert len(res.latencies_us) == 1 and res.latencies_us[0] >= 0


def test_bench_link_prints_its_figures(bundle, capsys):
    """`fleetlab bench link --json`: throughput and latency as figures (the keys, bit-exact soak), no threshold."""
    assert fleetlab_main(["bench", "link", "--frames", "1500", "--windows", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["soak_bit_exact"] and out["frames_sent"] >= 1500 and out["latency_windows"] == 1
    assert out["frames_per_s"] > 0 and out["latency_us_p50"] > 0
    assert out["ratio_to_rover_rate"] == round(out["frames_per_s"] / out["rover_frames_per_s"], 2)


def test_model_matches_the_c_node_across_a_reset(bundle, sim):
    from fleetlab.host_tools.wire.dbc import OutputAssembler, WindowEstimate, telemetry_frames

    est = CEstimator(find_artifact(build(bundle), "libslipest_host.so"))
    x = sim.samples_q[:500]
    fr = [telemetry_frames(i, x[i]) for i in range(500)]
    items = [WireItem(f) for i in range(250) for f in fr[i]] + [WireItem(control_frame(1))]
    items += [WireItem(f) for i in range(300, 500) for f in fr[i] if i != 450]
    model, asm, got = EstimatorModel(), OutputAssembler(), []
    for i, it in enumerate(items):
        model.feed(it, i)
        for out in est.handle(it.frame):
            r = asm.feed(out)
            if isinstance(r, WindowEstimate):
                got.append(r)
    want = model.windows()
    assert [(g.window_counter, g.n_samples, g.flags & 0x05) for g in got] == [
        (w.window_counter, w.n_samples, w.flags & 0x05) for w in want]
    c, exp = est.counters(), model.status_snapshot()
    assert all(c[k] == getattr(exp, k) for k in ("frames_received", "frames_rejected", "samples_dropped",
                                                  "windows_flagged", "windows_done"))


def test_a_csv_source_names_the_rows_it_dropped_for_nan(tmp_path):
    """A window CSV folder as a feature source: rows holding NaN/Inf cannot be sent, and the source's
    name (printed by emulate) counts them."""
    import numpy as np

    from fleetlab.data.csvio import read_windows_csv, write_windows_csv
    from fleetlab.host_tools.sources import csv_dir_source

    assert fleetlab_main(["simulate", "--out", str(tmp_path), "--scale", "0.1"]) == 0
    first = sorted(tmp_path.glob("*.csv"))[0]
    clean = csv_dir_source(tmp_path)
    table = read_windows_csv(first)
    table.features[0, 0] = np.nan
    write_windows_csv(first, table)
    damaged = csv_dir_source(tmp_path)
    assert "dropped" not in clean.name and "1 rows with NaN/Inf dropped" in damaged.name
    assert damaged.n_windows == clean.n_windows - 1
