"""`fleetlab emulate --estimates FILE` (issue 44): the C estimator's answer for each window of an imported bag,
written as CSV or as a rosbag2 MCAP that opens beside the input bag. The MCAP file is read back with the `mcap`
and `mcap-ros2-support` packages (not rosbags, which wrote it) and checked window by window against the torch
integer reference computed here from the imported raw samples."""

from __future__ import annotations

import csv
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.data.features_int import featurise_int, quantize_samples
from fleetlab.data.log_import import read_raw
from fleetlab.data.simulator import simulate_traverse
from fleetlab.data.simulator.bag import profile_toml, write_traverse_bag
from fleetlab.export.intref import argmax_lowest
from fleetlab.host_tools.emulator import default_bundle
from fleetlab.host_tools.estimates import (
    CSV_COLUMNS,
    DIAGNOSTICS_TOPIC,
    ERROR,
    ESTIMATE_TOPIC,
    ESTIMATE_TYPE,
    MSG_FILE,
    OK,
    WARN,
    _diagnostics,
)
from fleetlab.host_tools.verify.reference import Reference
from required import need_module

WINDOWS = 16


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    """A 32 s simulator bag, imported: 16 windows with their raw samples."""
    root = tmp_path_factory.mktemp("est")
    trace = simulate_traverse("leo", "analog_hall", 1.62, 32.0, seed=3)
    write_traverse_bag(root / "drive", trace, "leo", 1.62)
    (root / "leo.toml").write_text(profile_toml("leo", 1.62))
    assert fleetlab_main(["data", "import", str(root / "drive"), "--rover", str(root / "leo.toml"), "--out",
                          str(root / "imp"), "--no-progress"]) == 0
    return root


def _reference(root: Path):
    """Window start times, integer logits and saturations of the imported windows, computed here: the raw
    samples quantised as the CAN frames carry them, the integer features, the torch integer reference."""
    samples, _ = read_raw(root / "imp" / "drive.raw.npz")
    with np.load(root / "imp" / "drive.raw.npz") as z:
        starts = np.asarray(z["window_start_ns"], dtype=np.int64)
    iw = featurise_int(quantize_samples(samples))
    logits, sat = Reference.load(default_bundle()).q_logits(iw.features)
    return starts, logits, sat + iw.saturations


def _emulate(root: Path, out: Path, capsys) -> str:
    rc = fleetlab_main(["emulate", "--source", str(root / "imp"), "--link", "inproc", "--no-progress",
                        "--estimates", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert f"wrote {WINDOWS} window estimates to {out}" in text
    return text


def test_estimates_mcap_read_back_by_another_reader_is_bit_exact(imported, tmp_path, capsys):
    need_module("mcap.reader", "mcap")
    decoder = need_module("mcap_ros2.decoder", "mcap-ros2-support")
    from mcap.reader import make_reader

    out = tmp_path / "estimates.mcap"
    _emulate(imported, out, capsys)
    starts, logits, sat = _reference(imported)
    assert len(starts) == len(logits) == WINDOWS
    estimates, diagnostics = [], []
    with open(out, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[decoder.DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, msg in reader.iter_decoded_messages():
            if channel.topic == ESTIMATE_TOPIC:
                assert schema.name == ESTIMATE_TYPE and channel.message_encoding == "cdr"
                estimates.append((message.log_time, msg))
            else:
                assert channel.topic == DIAGNOSTICS_TOPIC and schema.name == "diagnostic_msgs/msg/DiagnosticArray"
                diagnostics.append((message.log_time, msg))
    assert len(estimates) == WINDOWS  # one estimate per window
    for k, (log_time, m) in enumerate(estimates):
        start = int(starts[k])
        assert m.window == k and m.window_counter == k
        assert m.window_start.sec * 10**9 + m.window_start.nanosec == start
        assert m.window_end.sec * 10**9 + m.window_end.nanosec == start + 2 * 10**9 == log_time
        assert list(m.logits) == [int(x) for x in logits[k]]  # bit for bit the torch integer reference
        assert m.slip_class == int(argmax_lowest(logits[k : k + 1])[0])
        assert m.class_name == ("low", "moderate", "high")[m.slip_class]
        assert m.saturations == int(sat[k]) and m.flags == (2 if sat[k] else 0) and m.n_samples == 100
        assert m.source_file == str(imported / "drive")
    # the estimator's STATUS reports: every 10 windows and at the end, at the end of the last window done
    assert [d.status[0].level for _, d in diagnostics] == [OK, OK]
    final_t, final = diagnostics[-1]
    values = {kv.key: kv.value for kv in final.status[0].values}
    assert final_t == int(starts[-1]) + 2 * 10**9
    assert values["windows_done"] == values["windows_bit_exact"] == str(WINDOWS)
    assert values["frames_rejected"] == values["samples_dropped"] == "0"
    assert final.status[0].message == f"{WINDOWS} windows, all bit-exact with the torch integer reference"


def test_estimates_mcap_opens_beside_the_input_bag(imported, tmp_path, capsys):
    """rosbags' AnyReader given the input bag and the estimates at once: one time line, the estimates inside
    the bag's span (its type comes from the schema in the file, not from rosbags' own types)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path / "beside.mcap"
    _emulate(imported, out, capsys)
    with AnyReader([imported / "drive", out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        types = {c.topic: c.msgtype for c in r.connections}
        assert types[ESTIMATE_TOPIC] == ESTIMATE_TYPE and types["/imu/data"] == "sensor_msgs/msg/Imu"
        conns = [c for c in r.connections if c.topic == ESTIMATE_TOPIC]
        times = [t for _, t, _ in r.messages(connections=conns)]
        bag = AnyReader([imported / "drive"])
        bag.open()
        lo, hi = bag.start_time, bag.end_time
        bag.close()
    assert len(times) == WINDOWS and lo < times[0] and times[-1] <= hi


def test_estimates_csv(imported, tmp_path, capsys):
    out = tmp_path / "e.csv"
    _emulate(imported, out, capsys)
    starts, logits, sat = _reference(imported)
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == WINDOWS
    for k, r in enumerate(rows):
        assert int(r["start_ns"]) == starts[k] and int(r["end_ns"]) == starts[k] + 2 * 10**9
        assert [int(r["logit_low"]), int(r["logit_moderate"]), int(r["logit_high"])] == [int(x) for x in logits[k]]
        assert int(r["saturations"]) == sat[k] and r["bit_exact"] == "1" and r["source_file"] == str(imported / "drive")


def test_estimates_path_must_be_csv_or_mcap(imported, tmp_path, capsys):
    rc = fleetlab_main(["emulate", "--source", str(imported / "imp"), "--link", "inproc", "--no-progress",
                        "--estimates", str(tmp_path / "e.json")])
    assert rc == 1 and "must end in .csv or .mcap" in capsys.readouterr().err
    assert not (tmp_path / "e.json").exists()


def test_the_message_type_has_one_definition():
    from fleetlab.host_tools.estimates import typestore

    ts = typestore()
    fields = [name for name, _ in ts.fielddefs[ESTIMATE_TYPE][1]]
    assert fields[:3] == ["header", "window_start", "window_end"] and "logits" in fields
    assert MSG_FILE.read_text().startswith("# slipest_msgs/msg/SlipEstimate")


def _status(done: int, rejected: int = 0) -> SimpleNamespace:
    return SimpleNamespace(windows_done=done, frames_received=3 * 100 * done, frames_rejected=rejected,
                           samples_dropped=0, windows_flagged=0, model_hash=0x1234ABCD, lib_version=0x0100)


@pytest.mark.parametrize("exact, rejected, problems, levels", [
    ([True] * 4, 0, [], [OK, OK]),
    ([True] * 4, 3, [], [OK, WARN]),  # counters that rose: WARN
    ([True, False, True, True], 0, [], [OK, ERROR]),  # a window that differs from the reference: ERROR
    ([True] * 4, 0, ["frames_received 10 != expected 12"], [OK, ERROR]),  # a counter that differs: ERROR
])
def test_diagnostics_levels(exact, rejected, problems, levels):
    seg = SimpleNamespace(verdicts=[SimpleNamespace(bit_exact=e) for e in exact], status_problems=problems,
                          statuses=[_status(1), _status(4, rejected)])
    result = SimpleNamespace(segments=[seg], model_hash_problems=[], host_rx_errors=[])
    rows = [SimpleNamespace(window=k, start_ns=2 * k * 10**9, end_ns=2 * (k + 1) * 10**9) for k in range(4)]
    diags = _diagnostics(result, rows)
    assert [d[1] for d in diags] == levels
    assert [d[0] for d in diags] == [2 * 10**9, 8 * 10**9]
    assert diags[-1][3]["windows_bit_exact"] == str(sum(exact)) and diags[-1][3]["model_hash"] == "1234abcd"
