"""`fleetlab stream` / `fleetlab monitor`: python-can buses, logs and replay, serial, SocketCAN errors."""

from __future__ import annotations

import re
import socket
import threading
from pathlib import Path

import can
import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.export.vectors import read_vectors
from fleetlab.host_tools.emulator import build, default_bundle, find_artifact
from fleetlab.host_tools.pacing import SimulatedClock
from fleetlab.host_tools.links import InprocLink, open_can_bus
from fleetlab.host_tools.monitor import monitor_bus, monitor_log
from fleetlab.host_tools.sources import FeatureSource
from fleetlab.host_tools.stream import TrafficLog, stream, timed_frames


@pytest.fixture(scope="module")
def lib():
    return find_artifact(build(default_bundle()), "libslipest_host.so")


@pytest.fixture(scope="module")
def n_vectors():
    return len(read_vectors(default_bundle()).q_inputs)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_stream_virtual_logs_and_the_log_replays(tmp_path, n_vectors, suffix, capsys):
    log = tmp_path / f"traffic{suffix}"
    rc = fleetlab_main(["stream", "can", "--interface", "virtual", "--source", "vectors", "--log", str(log),
                        "--quiet"])
    assert rc == 0
    assert f"received {n_vectors} estimates" in capsys.readouterr().out
    # the log holds both directions; the monitor decodes every estimate from it
    stats = monitor_log(log, show=None)
    assert len(stats.estimates) == n_vectors and stats.unknown == 0 and not stats.problems
    assert all(e.flags & 0x08 for e in stats.estimates)  # fed as FEATURES frames
    # replaying the log as a source sends only the host's frames again: same answers
    rc = fleetlab_main(["stream", "can", "--interface", "virtual", "--source", str(log), "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    assert f"received {n_vectors} estimates" in out
    # and says what it did not send again: every frame of the log is either sent or counted
    in_log = sum(1 for m in can.LogReader(str(log)))
    sent = int(re.search(r"sent (\d+) frames", out).group(1)) - 2  # the CONTROL reset and status of the replay
    counted = re.search(r"not sent again: (\d+) frames the host does not send", out)
    assert counted and sent + int(counted.group(1)) == in_log, out


def test_estimates_match_the_bundle_vectors(lib, n_vectors):
    vec = read_vectors(default_bundle())
    src = FeatureSource("vectors", np.asarray(vec.q_inputs, np.int16))
    with InprocLink(lib) as link:
        stats = stream(link, timed_frames(src), False, TrafficLog(None), progress=False)
    assert len(stats.estimates) == n_vectors
    got = np.array([e.logits for e in stats.estimates])
    assert np.array_equal(got, np.asarray(vec.q_logits))
    assert stats.status is not None and stats.status.frames_received == stats.frames_sent


def test_monitor_watches_a_live_bus(lib):
    channel = "fleetlab-monitor-test"
    vec = read_vectors(default_bundle())
    src = FeatureSource("vectors", np.asarray(vec.q_inputs[:20], np.int16))
    lines: list[str] = []
    watcher = can.Bus(interface="virtual", channel=channel)
    result = {}
    t = threading.Thread(target=lambda: result.setdefault("s", monitor_bus(watcher, duration=10, count=20,
                                                                              show=lines.append)))
    t.start()
    with InprocLink(lib, channel=channel) as link:
        stream(link, timed_frames(src), False, TrafficLog(None), progress=False)
    t.join(timeout=15)
    watcher.shutdown()
    stats = result["s"]
    assert len(stats.estimates) == 20
    assert sum(line.startswith("estimate window") for line in lines) == 20
    assert any(line.startswith("status:") for line in lines)  # every 10th window sends status
    # the host's own frames are DBC frames too, decoded silently; nothing unknown
    assert stats.unknown == 0


def test_stream_serial_and_slcan_to_the_emulator(capsys):
    rc = fleetlab_main(["stream", "serial", "--port", "emulator", "--source", "vectors", "--quiet"])
    assert rc == 0, capsys.readouterr()
    rc = fleetlab_main(["stream", "can", "--interface", "slcan", "--channel", "emulator", "--source", "sim",
                        "--scale", "0.03", "--limit", "12", "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "(12 windows)" in out and "received 12 estimates" in out


def test_realtime_pacing_follows_50_hz(lib):
    rng = np.random.default_rng(0)
    from fleetlab.host_tools.sources import TelemetrySource

    src = TelemetrySource("noise", rng.integers(-500, 500, size=(100, 7)).astype(np.int16), [])
    clock = SimulatedClock()  # moves only when the stream waits for a due time: no wall time in the check
    with InprocLink(lib) as link:
        stats = stream(link, timed_frames(src), True, TrafficLog(None), progress=False, clock=clock)
    assert len(stats.estimates) == 1 and stats.frames_sent == 300 + 2  # with CONTROL reset and status
    # paced at 50 Hz: the stream waited once per sample after the first (its three frames share a due time)
    # and its clock stands at the 100th sample's due time, 99 periods after the first
    assert stats.pacer.waits == 99
    assert stats.pacer.elapsed() == pytest.approx(99 / 50)


def _socketcan_available(channel: str) -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (AttributeError, OSError):
        return False
    return Path(f"/sys/class/net/{channel}").exists()


def test_socketcan_works_or_fails_clearly(capsys):
    if _socketcan_available("vcan0"):
        bus = open_can_bus("socketcan", "vcan0")
        peer = open_can_bus("socketcan", "vcan0")
        bus.send(can.Message(arbitration_id=0x0F0, data=[2, 0], is_extended_id=False))
        msg = peer.recv(timeout=2)
        bus.shutdown()
        peer.shutdown()
        assert msg is not None and msg.arbitration_id == 0x0F0
        return
    with pytest.raises(OSError, match="SocketCAN"):
        open_can_bus("socketcan", "vcan0")
    rc = fleetlab_main(["stream", "can", "--interface", "socketcan", "--channel", "vcan0", "--source", "vectors"])
    err = capsys.readouterr().err
    assert rc == 1 and "SocketCAN" in err and "Traceback" not in err


def test_bad_sources_give_one_line_errors(tmp_path, capsys):
    rc = fleetlab_main(["stream", "can", "--source", str(tmp_path / "missing.log")])
    assert rc == 1 and "missing.log" in capsys.readouterr().err
    rc = fleetlab_main(["emulate", "--inject", "bit_flip", "--source", "vectors"])
    assert rc == 1 and "bit_flip" in capsys.readouterr().err
    rc = fleetlab_main(["monitor", "can", "--replay", str(tmp_path / "none.asc")])
    assert rc == 1 and "none.asc" in capsys.readouterr().err


def test_a_malformed_can_log_is_one_line_naming_the_file_and_how_far_it_was_read(tmp_path, capsys):
    """python-can's candump reader raises 'not enough values to unpack' on a broken line: both commands that
    read logs say which file, and after how many good frames."""
    log = tmp_path / "cut.log"
    log.write_text("(0.100000) vcan0 123#0011\n(0.200000) vcan0 124#22\nthe rest was lost\n")
    for args in (["monitor", "can", "--replay", str(log)], ["stream", "can", "--source", str(log), "--quiet"]):
        rc = fleetlab_main(args)
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 1 and err, args
        assert "cut.log: malformed python-can log after 2 frames" in err[-1] and "Traceback" not in "".join(err), err
