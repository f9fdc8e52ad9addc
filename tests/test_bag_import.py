"""`fleetlab data import` on odd and damaged rosbag2 bags (issue 44): a folder holding only a `.mcap`, a
bag cut short by a crash (salvaged up to its last whole message, the loss said in one line and counted),
and `[import] stamps` (header stamps or the bag's log time, with the hint when the header stamps are zero)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.data.csvio import read_windows_csv
from fleetlab.data.log_import import import_log
from fleetlab.data.mcap_stream import scan_mcap
from fleetlab.data.rover_profile import ProfileError, load_profile
from fleetlab.data.simulator import simulate_traverse
from fleetlab.data.simulator.bag import profile_toml, write_traverse_bag

SECONDS = 32.0  # the traverse: 1600 samples at 50 Hz, 16 windows; 6401 messages on four topics


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("bags")
    trace = simulate_traverse("leo", "analog_hall", 9.81, SECONDS, seed=11)
    write_traverse_bag(root / "good", trace, "leo", 9.81)
    (root / "leo.toml").write_text(profile_toml("leo", 9.81))
    return root


def _import(capsys, *argv: str) -> tuple[int, str, str]:
    rc = fleetlab_main(["data", "import", *argv, "--no-progress"])
    out, err = capsys.readouterr()
    return rc, out, err


def _mcap(bag: Path) -> Path:
    (f,) = (bag / "good").glob("*.mcap")
    return f


def _windows(folder: Path, stem: str):
    return read_windows_csv(folder / f"{stem}.csv")


# ---------------------------------------------------------------- a bare .mcap


@pytest.mark.parametrize("form", ["folder without metadata.yaml", "the .mcap file itself"])
def test_a_bare_mcap_opens(bag, tmp_path, capsys, form):
    """A folder holding only the .mcap (the recorder never wrote metadata.yaml), or the file given as the path,
    imports like the whole rosbag2 folder. Before issue 44 the folder failed with 'truncated or not a bag?'."""
    if form.startswith("folder"):
        src = tmp_path / "bare"
        src.mkdir()
        shutil.copy(_mcap(bag), src / "rec_0.mcap")
    else:
        src = _mcap(bag)
    rc, out, err = _import(capsys, str(src), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "o"))
    assert rc == 0, err
    assert "salvaged" not in out and "bag cut short" not in out  # a whole file: nothing salvaged, nothing to say
    rc, _, err = _import(capsys, str(bag / "good"), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "ref"))
    assert rc == 0, err
    got, ref = _windows(tmp_path / "o", src.stem if src.is_file() else src.name), _windows(tmp_path / "ref", "good")
    assert len(got) == len(ref) == 16
    np.testing.assert_array_equal(got.features, ref.features)
    np.testing.assert_array_equal(got.label, ref.label)


# ---------------------------------------------------------------- a bag cut short


@pytest.mark.parametrize("share", [0.3, 0.6, 0.9])
@pytest.mark.parametrize("with_metadata", [True, False], ids=["with-metadata", "bare"])
def test_a_bag_cut_short_is_salvaged_and_the_loss_said_in_one_line(bag, tmp_path, capsys, share, with_metadata):
    """The first `share` of the bag's bytes, as a crash leaves them (no summary, no index, no footer, the last
    chunk cut in the middle): the import reads it up to the last whole message, windows what that holds exactly
    as the whole bag would, and says in one warning line what was salvaged and what was lost."""
    whole = _mcap(bag).read_bytes()
    src = tmp_path / "cut"
    src.mkdir()
    (src / "cut_0.mcap").write_bytes(whole[: int(len(whole) * share)])
    if with_metadata:  # metadata.yaml of the whole recording (its counts say how much was lost)
        meta = (bag / "good" / "metadata.yaml").read_text()
        (src / "metadata.yaml").write_text(meta.replace("good.mcap", "cut_0.mcap"))
    rc, out, err = _import(capsys, str(src), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "o"))
    assert rc == 0, err
    said = [ln for ln in out.splitlines() if "salvaged" in ln or "cut short" in ln]
    assert len(said) == 1 and said[0].startswith("warning: "), out  # one line
    line = said[0]
    scan = scan_mcap(src / "cut_0.mcap")
    assert not scan.complete and 0 < len(scan.messages) < 6401
    seconds = (scan.messages[-1][1] - scan.messages[0][1]) / 1e9
    assert "bag cut short (cut_0.mcap: the file ends inside a chunk" in line
    assert f"salvaged {len(scan.messages)} messages ({seconds:.1f} s)" in line
    assert "the summary/index" in line
    if with_metadata:  # the recording ends SECONDS after its first message
        lost_s = (scan.messages[0][1] + int(SECONDS * 1e9) - scan.messages[-1][1]) / 1e9
        assert f"lost {6401 - len(scan.messages)} messages and {lost_s:.1f} s (metadata.yaml lists 6401" in line
    else:
        assert "how much is unknown: no metadata.yaml" in line
    # a recorder writes in time order: the salvaged messages are the first ones of every topic
    n_samples = len(scan.messages) // 4
    assert abs(n_samples - share * 1600) < 0.06 * 1600
    report = json.loads((tmp_path / "o" / "import_report.json").read_text())["logs"][0]
    assert line[len("warning: "):] in report["notes"]
    assert report["drops"].get("bag_lost_bytes", 0) == scan.lost_bytes
    assert ("bag_lost_messages" in report["drops"]) == with_metadata
    # what it holds: exactly the whole bag's first windows (each needs 2 s of every topic and one more pose)
    got = _windows(tmp_path / "o", "cut")
    rc, _, err = _import(capsys, str(bag / "good"), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "ref"))
    ref = _windows(tmp_path / "ref", "good")
    assert len(got) == (n_samples - 1) // 100 > 0
    np.testing.assert_array_equal(got.features, ref.features[: len(got)])
    np.testing.assert_array_equal(got.label, ref.label[: len(got)])


def test_a_cut_zstd_bag_gives_the_whole_messages_of_its_cut_chunk(bag, tmp_path):
    """Chunks compressed with zstd (rosbag2's storage preset): the cut chunk is decompressed as a stream, so
    its first messages are salvaged too."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    w = Writer(tmp_path / "z", version=9, storage_plugin=StoragePlugin.MCAP)
    w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with AnyReader([bag / "good"], default_typestore=ts) as r, w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in r.connections}
        for c, log_ns, raw in r.messages():
            w.write(conns[c.id], log_ns, raw)
    whole = next((tmp_path / "z").glob("*.mcap")).read_bytes()
    (tmp_path / "cut").mkdir()
    (tmp_path / "cut" / "cut.mcap").write_bytes(whole[: int(len(whole) * 0.6)])
    scan = scan_mcap(tmp_path / "cut" / "cut.mcap")
    assert scan.cut_chunk_messages > 0 and "ends inside a chunk" in scan.stop
    profile = load_profile(bag / "leo.toml")
    res, ref = import_log(tmp_path / "cut", profile, progress=False), import_log(bag / "good", profile, progress=False)
    n = res.windows_kept
    assert n == (len(scan.messages) // 4 - 1) // 100 > 0
    assert len([note for note in res.notes if "bag cut short" in note]) == 1
    np.testing.assert_array_equal(res.segments[0].windows.features, ref.segments[0].windows.features[:n])


def test_a_bag_cut_before_its_first_whole_message_is_one_error_line(bag, tmp_path, capsys):
    cut = tmp_path / "early.mcap"
    cut.write_bytes(_mcap(bag).read_bytes()[:3000])
    rc, _, err = _import(capsys, str(cut), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "o"))
    assert rc == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "early.mcap" in lines[0] and "no messages" in lines[0] and "ends inside a chunk" in lines[0]


def test_a_damaged_chunk_ends_the_read_there(bag, tmp_path):
    """A chunk whose bytes were overwritten (its CRC kept): the read stops at it and keeps what came before."""
    data = bytearray(_mcap(bag).read_bytes())
    whole = scan_mcap(_mcap(bag))
    assert whole.complete and whole.chunks >= 2 and len(whole.messages) == 6401
    # the second chunk record: set a CRC on it that its records do not have
    from fleetlab.data.mcap_stream import MAGIC, OP_CHUNK, _RECORD_HEAD

    pos, chunks = len(MAGIC), 0
    while True:
        op, length = _RECORD_HEAD.unpack_from(data, pos)
        if op == OP_CHUNK:
            chunks += 1
            if chunks == 2:
                break
        pos += _RECORD_HEAD.size + length
    crc_at = pos + _RECORD_HEAD.size + 24
    data[crc_at : crc_at + 4] = b"\x01\x02\x03\x04"
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "d.mcap").write_bytes(bytes(data))
    scan = scan_mcap(tmp_path / "d" / "d.mcap")
    assert not scan.complete and scan.stop.startswith(f"a damaged record at byte {pos}") and "CRC" in scan.stop
    assert 0 < len(scan.messages) < 6401 and scan.whole_bytes == pos
    res = import_log(tmp_path / "d", load_profile(bag / "leo.toml"), progress=False)
    assert any(note.startswith(f"{tmp_path / 'd'}: bag damaged (d.mcap: a damaged record") for note in res.notes)
    assert 0 < res.windows_kept < 16


# ---------------------------------------------------------------- [import] stamps


def _zero_header_stamps(src: Path, dst: Path, topics: set[str]) -> Path:
    """A copy of the bag whose messages on `topics` carry a zero header stamp (a driver that never sets it);
    the log time (when the recorder received each message) stays."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([src], default_typestore=ts) as r, Writer(dst, version=9) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in r.connections}
        for c, log_ns, raw in r.messages():
            if c.topic in topics:
                msg = r.deserialize(raw, c.msgtype)
                msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
                raw = ts.serialize_cdr(msg, c.msgtype)
            w.write(conns[c.id], log_ns, raw)
    return dst


def _with_stamps(bag: Path, tmp_path: Path, value: str) -> Path:
    p = tmp_path / f"stamps_{value}.toml"
    p.write_text(profile_toml("leo", 9.81).replace("max_gap_s = 0.5", f'max_gap_s = 0.5\nstamps = "{value}"'))
    return p


def test_zero_header_stamps_say_set_stamps_log_and_log_stamps_import_them(bag, tmp_path, capsys):
    zero = _zero_header_stamps(bag / "good", tmp_path / "zero", {"/imu/data"})
    rc, _, err = _import(capsys, str(zero), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "o"))
    assert rc == 1 and len(err.strip().splitlines()) == 1, err
    assert '/imu/data: the header stamps are all zero: set [import] stamps = "log"' in err
    # the bag's log time instead: the simulator logs each message at its stamp, so the windows are the same
    rc, _, err = _import(capsys, str(zero), "--rover", str(_with_stamps(bag, tmp_path, "log")), "--out",
                         str(tmp_path / "log"))
    assert rc == 0, err
    rc, _, err = _import(capsys, str(bag / "good"), "--rover", str(bag / "leo.toml"), "--out", str(tmp_path / "ref"))
    assert rc == 0, err
    got, ref = _windows(tmp_path / "log", "zero"), _windows(tmp_path / "ref", "good")
    assert len(got) == len(ref) == 16
    np.testing.assert_array_equal(got.features, ref.features)
    np.testing.assert_array_equal(got.d_actual, ref.d_actual)


def test_log_stamps_take_the_log_time_not_the_header(bag, tmp_path):
    """stamps = "log" puts each message at its log time even where the header says otherwise."""
    from fleetlab.data.log_sources import read_bag

    header = read_bag(bag / "good", load_profile(bag / "leo.toml"), progress=False)[0]
    zero = _zero_header_stamps(bag / "good", tmp_path / "zero", {"/imu/data", "/joint_states", "/odometry/filtered",
                                                                "/ground_truth/pose"})
    log = read_bag(zero, load_profile(_with_stamps(bag, tmp_path, "log")), progress=False)[0]
    for section in header:
        np.testing.assert_array_equal(log[section].t_ns, header[section].t_ns)
        assert log[section].t_ns[0] == 1_700_000_000 * 10**9
    # and header stamps of that bag are all zero: an error naming the first section's topic
    with pytest.raises(ValueError, match=r"/joint_states: the header stamps are all zero"):
        read_bag(zero, load_profile(bag / "leo.toml"), progress=False)


@pytest.mark.parametrize("text, match", [
    ('stamps = "receive"', r'import\.stamps: must be "header" .* or "log"'),
    ('stamps = "log"', r"import\.stamps: applies to bags only"),
])
def test_stamps_key_mistakes(tmp_path, text, match):
    if "receive" in text:
        body = profile_toml("leo", 9.81).replace("max_gap_s = 0.5", f"max_gap_s = 0.5\n{text}")
    else:  # a time-series CSV profile
        body = ('[rover]\nname = "r"\nwheel_radius_m = 0.1\n[wheels]\nfile = "w.csv"\ntime_column = "t"\n'
                'velocity_columns = ["v"]\neffort_columns = ["i"]\n[imu]\nfile = "i.csv"\ntime_column = "t"\n'
                'acc_columns = ["x", "y", "z"]\nincludes_gravity = false\n[attitude]\nfile = "i.csv"\n'
                f'time_column = "t"\nroll_column = "r"\npitch_column = "p"\n[import]\n{text}\n')
    (tmp_path / "p.toml").write_text(body)
    with pytest.raises(ProfileError, match=match):
        load_profile(tmp_path / "p.toml")
    assert load_profile(_with_stamps_default(tmp_path)).stamps == "header"


def _with_stamps_default(tmp_path: Path) -> Path:
    (tmp_path / "d.toml").write_text(profile_toml("leo", 9.81))
    return tmp_path / "d.toml"
