"""Long-running nodes (issue 42 item 5): `fleetlab stream` and `fleetlab monitor` against an estimator that ran
before and keeps running after. The node's STATUS counters are cumulative over its whole life; each command reads
them as differences from their values at its own start (and across a 32-bit / 16-bit wrap)."""

from __future__ import annotations

import re
import threading

import can
import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.export.vectors import read_vectors
from fleetlab.host_tools.emulator import EmulatorProcess, build, default_bundle, find_artifact
from fleetlab.host_tools.links import InprocLink, link_class
from fleetlab.host_tools.monitor import Monitor, monitor_bus
from fleetlab.host_tools.sources import FeatureSource
from fleetlab.host_tools.stream import TrafficLog, stream, timed_frames
from fleetlab.host_tools.wire.dbc import StatusReport

WINDOWS = 12


def test_three_streams_in_a_row_to_one_running_emulator(capsys):
    """One slipest_emu, three `fleetlab stream can --interface slcan` runs: each one passes and reports its own
    frames, not the node's lifetime totals (before the fix the second run said 'PROBLEM: -N frames sent but not
    received' and returned 1)."""
    emu = EmulatorProcess.for_bundle(None, link_class("slcan").emulator_protocol)
    pty = emu.start()
    try:
        for run in range(3):
            rc = fleetlab_main(["stream", "can", "--interface", "slcan", "--channel", pty, "--source", "sim",
                                "--scale", "0.03", "--limit", str(WINDOWS), "--quiet"])
            out = capsys.readouterr().out
            assert rc == 0, (run, out)
            assert f"({WINDOWS} windows)" in out and f"received {WINDOWS} estimates" in out, (run, out)
            assert "PROBLEM" not in out, (run, out)
            sent = int(re.search(r"sent (\d+) frames", out).group(1))
            assert sent == 3 * 100 * WINDOWS + 2, out  # with CONTROL reset and status (not the baseline request)
            got = re.search(r"estimator: frames received (\d+), rejected (\d+), samples dropped (\d+), "
                            r"windows flagged (\d+), windows done (\d+)", out)
            assert got, out
            assert [int(v) for v in got.groups()] == [sent, 0, 0, 0, WINDOWS], (run, out)
            assert emu.running
    finally:
        emu.stop()


@pytest.fixture(scope="module")
def lib():
    return find_artifact(build(default_bundle()), "libslipest_host.so")


def test_stream_function_counts_from_its_own_start(lib):
    """The same through the library call on one in-process estimator: stats.status counts what this stream
    caused, stats.node_status is the node's report as it came, stats.node_start the baseline."""
    vec = read_vectors(default_bundle())
    src = FeatureSource("vectors", np.asarray(vec.q_inputs[:15], np.int16))
    with InprocLink(lib) as link:
        for run in range(3):
            stats = stream(link, timed_frames(src), False, TrafficLog(None), progress=False)
            assert len(stats.estimates) == 15 and not stats.rx_errors, run
            st = stats.status
            assert st is not None
            assert (st.frames_received, st.frames_rejected, st.samples_dropped, st.windows_flagged,
                    st.windows_done) == (stats.frames_sent, 0, 0, 0, 15), run
            # the node's own totals keep growing over the three runs (the baseline requests count too)
            assert stats.node_status.windows_done == 15 * (run + 1)
            assert stats.node_status.frames_received == (run + 1) * (stats.frames_sent + 1)


def test_counter_differences_wrap():
    from fleetlab.host_tools.stream import counter_delta, status_delta

    assert counter_delta(5, 0xFFFFFFFE) == 7
    assert counter_delta(3, 0xFFFE, bits=16) == 5
    assert counter_delta(10, 4) == 6
    start = StatusReport(0xABCD, 0x100, 0xFFF0, 0xFFFFFF00, 0xFFFFFFFF, 7, 0)
    now = StatusReport(0xABCD, 0x100, 0x0010, 0x00000100, 0x00000001, 9, 1)
    d = status_delta(now, start)
    assert (d.windows_done, d.frames_received, d.frames_rejected, d.samples_dropped, d.windows_flagged) == \
        (0x20, 0x200, 2, 2, 1)
    assert (d.model_hash, d.lib_version) == (0xABCD, 0x100)  # not counters: as reported
    assert status_delta(now, None) is now


def test_monitor_shows_counters_since_it_started(lib):
    """A monitor started on a bus whose node ran before shows its counters as they rise during the watch."""
    channel = "fleetlab-monitor-long-running"
    vec = read_vectors(default_bundle())
    src = FeatureSource("vectors", np.asarray(vec.q_inputs[:20], np.int16))
    with InprocLink(lib, channel=channel) as link:
        stream(link, timed_frames(src), False, TrafficLog(None), progress=False)  # the node's earlier life
        lines: list[str] = []
        watcher = can.Bus(interface="virtual", channel=channel)
        result = {}
        t = threading.Thread(target=lambda: result.setdefault("s", monitor_bus(watcher, duration=10, count=20,
                                                                                  show=lines.append)))
        t.start()
        stream(link, timed_frames(src), False, TrafficLog(None), progress=False)
        t.join(timeout=15)
        watcher.shutdown()
    stats = result["s"]
    assert len(stats.estimates) == 20
    status = [line for line in lines if line.startswith("status:")]
    # the monitor's first status is its baseline, shown as the node's totals; the next one (window 20 of this
    # stream, the node's 40th) counts from there
    assert len(status) >= 2, lines
    assert "windows 20 rx" in status[0] and "since the monitor started" not in status[0], status
    assert "since the monitor started: windows 10 " in status[1], status


def test_monitor_line_is_a_difference_after_the_first_status():
    mon = Monitor()
    first = StatusReport(0x11, 0x100, 65530, 4294967290, 3, 0, 0)
    later = StatusReport(0x11, 0x100, 4, 10, 3, 1, 0)
    assert mon.status_line(first).startswith("status: model 00000011 v1.0 windows 65530 rx 4294967290")
    line = mon.status_line(later)
    assert "since the monitor started: windows 10 rx 16 rejected 0 dropped 1 flagged 0" in line, line


def test_upload_rehearsal_reports_counters_from_its_own_start(bdir, new_bundle, samples):
    """`fleetlab upload --rehearse` on a CANopen node that ran before (telemetry, a refused upload): the report's
    counters are what the rehearsal did, the totals beside them. A second rehearsal right after cannot run (the
    node's sample counter is past the rehearsal's start at 0, and the CANopen profile has no grid reset): it
    says so instead of 'is it operational?'."""
    import canopen

    from fleetlab.canopen_od import objects as od
    from fleetlab.host_tools.canopen_master import EstimateCollector
    from fleetlab.host_tools.canopen_session import eds_for, stream_telemetry
    from fleetlab.host_tools.emulator import HOST_LIBRARY_TARGET
    from fleetlab.host_tools.upload import open_tapped, rehearse
    from fleetlab.host_tools.verify.upload_faults import faulty_image
    from canopen_helpers import EXAMPLE, NODE_ID

    image = (new_bundle / "model.img").read_bytes()
    lib = find_artifact(bdir, f"lib{HOST_LIBRARY_TARGET}.so")
    session, tap = open_tapped("inproc", eds_for(bdir), NODE_ID, lib=lib)
    with session:
        m = session.master
        # the node's earlier life: 3 windows whose sample counters end at 65535 (the rehearsal's 0 comes next)
        m.node.tpdo.read()
        col = EstimateCollector(m.node)
        m.node.nmt.state = "OPERATIONAL"
        assert stream_telemetry(session, samples[:300], col, first_counter=65536 - 300) == 3
        assert col.wait_for(3, 20)
        with pytest.raises(canopen.SdoAbortedError):
            m.upload(faulty_image("wrong_arch", image))
        m.node.nmt.state = "PRE-OPERATIONAL"
        r = rehearse(session, tap, image, new_bundle, EXAMPLE, windows=3, scale=0.1)
        assert r["boot_model_bit_exact"] and r["new_model_bit_exact"], r
        c, total = r["counters"], r["counters_total"]
        assert (c["windows_done"], c["frames_received"], c["frames_rejected"], c["rpdo_received"]) == (6, 1800, 0, 1800)
        # the CiA 302-3 start restarts the node's application (its boot-up): the totals are those since the start
        assert (total["windows_done"], total["frames_received"]) == (3, 900)
        s, stotal = r["store_counters"], r["store_counters_total"]
        assert set(s) == set(od.STORE_COUNTERS)
        assert (s["uploads_started"], s["images_accepted"], s["activations"]) == (1, 1, 1)
        assert sum(s[k] for k in s if k.startswith("refused_")) == 0
        assert stotal["uploads_started"] == 2 and sum(stotal[k] for k in stotal if k.startswith("refused_")) == 1
        # the node runs on, but a rehearsal from sample 0 again is refused by it: a clear line
        with pytest.raises(OSError, match=r"rejected \d+ telemetry frames .* ran before"):
            rehearse(session, tap, image, new_bundle, new_bundle, windows=3, scale=0.1)
