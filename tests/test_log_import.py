"""`fleetlab data import`: real rosbag2 files (MCAP and sqlite3, written and read by `rosbags`) and
time-series CSVs into Fleet-To-Lab windows, against the simulator's own CSVs and an independent numpy
computation; every bad input ends in one clear line or a counted drop."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.data.csvio import read_windows_csv
from fleetlab.data.dataset import load_dataset
from fleetlab.data.log_import import import_log
from fleetlab.data.rover_profile import ProfileError, load_profile
from fleetlab.data.simulator import simulate_traverse
from fleetlab.data.simulator.bag import profile_name, profile_toml, write_traverse_bag

REPO = Path(__file__).resolve().parents[1]
# Features of an imported simulator bag equal the simulator's within this (docs/your_rover.md): the
# quaternion round trip and the gravity taken out again cost a few ulp.
RTOL, ATOL = 1e-9, 1e-9


def _import(capsys, *argv: str) -> tuple[int, str, str]:
    rc = fleetlab_main(["data", "import", *argv, "--no-progress"])
    out, err = capsys.readouterr()
    return rc, out, err


def _simulate_and_import(root: Path, storage: str):
    """Simulator bags of one storage, each imported with its profile (one folder per profile), no role given."""
    assert fleetlab_main(["simulate", "--out", str(root / "sim"), "--scale", "0.02", "--seed", "5",
                          "--bag", str(root / "bags"), "--bag-storage", storage]) == 0
    manifest = json.loads((root / "sim" / "dataset.json").read_text())
    by_profile: dict[str, list[str]] = {}
    for entry in manifest["files"].values():
        by_profile.setdefault(entry["bag"]["profile"], []).append(entry["bag"]["path"])
    for profile, bags in by_profile.items():
        rc = fleetlab_main(["data", "import", *(str(root / "bags" / b) for b in bags), "--rover",
                            str(root / "bags" / profile), "--out", str(root / "imp" / profile), "--no-progress"])
        assert rc == 0
    return root, storage, manifest, by_profile


@pytest.fixture(scope="module")
def mcap_import(tmp_path_factory):
    return _simulate_and_import(tmp_path_factory.mktemp("sim_mcap"), "mcap")


@pytest.fixture(scope="module")
def sqlite3_import(tmp_path_factory):
    return _simulate_and_import(tmp_path_factory.mktemp("sim_sqlite3"), "sqlite3")


@pytest.fixture(params=["mcap", "sqlite3"])
def imported(request):
    return request.getfixturevalue(f"{request.param}_import")


def test_round_trip_simulator_bag_gives_the_simulators_windows(imported, capsys):
    root, storage, manifest, by_profile = imported
    assert {"leo_earth.rover.toml", "leo_moon.rover.toml"} <= set(by_profile)
    suffix = ".mcap" if storage == "mcap" else ".db3"
    n_files = 0
    for profile, bags in by_profile.items():
        out = root / "imp" / profile
        assert all(any((root / "bags" / b).glob("*" + suffix)) for b in bags)
        for b in bags:
            sim, imp = read_windows_csv(root / "sim" / f"{b}.csv"), read_windows_csv(out / f"{b}.csv")
            assert len(imp) == len(sim) > 0
            assert np.array_equal(imp.label, sim.label)
            assert np.array_equal(imp.n_samples, sim.n_samples)
            assert np.array_equal(imp.duration_s, sim.duration_s)
            np.testing.assert_allclose(imp.features, sim.features, rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(imp.d_actual, sim.d_actual, rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(imp.d_commanded, sim.d_commanded, rtol=RTOL, atol=ATOL)
            n_files += 1
        report = json.loads((out / "import_report.json").read_text())
        assert all(log["drops"] == {} and log["windows_kept"] == log["windows_cut"] for log in report["logs"])
    assert n_files == len(manifest["files"])


def test_simulator_bag_imu_carries_gravity(mcap_import):
    """The bag's IMU is raw specific force: mean acc_z about g, which the import takes out again."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    root = mcap_import[0]
    bag = next(p for p in sorted((root / "bags").iterdir()) if p.name.startswith("earth_"))
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        conns = [c for c in r.connections if c.topic == "/imu/data"]
        assert conns[0].msgtype == "sensor_msgs/msg/Imu"
        z = [r.deserialize(raw, c.msgtype).linear_acceleration.z for c, _, raw in r.messages(connections=conns)]
    assert abs(np.mean(z) - 9.81) < 0.2
    imp = read_windows_csv(root / "imp" / "leo_earth.rover.toml" / f"{bag.name}.csv")
    assert abs(imp.features[:, 8].mean()) < 0.2  # feat_acc_z_mean: gravity-free


def test_example_profile_is_the_simulators():
    """docs/rover_profiles/leo_moon.rover.toml is what `simulate --bag` writes for the target rover."""
    example = REPO / "docs" / "rover_profiles" / profile_name("leo", 1.62)
    assert example.read_text() == profile_toml("leo", 1.62)
    p = load_profile(example)
    assert p.kind == "bag" and p.includes_gravity and p.gravity_m_s2 == 1.62 and p.ground_truth is not None


# ---------------------------------------------------------------- time-series CSV


def _write_csv(path: Path, header: list[str], cols: list[np.ndarray]) -> None:
    rows = np.column_stack(cols)
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")


CSV_PROFILE = """
[rover]
name = "bench_rover"
wheel_radius_m = 0.1

[wheels]
file = "wheels_*.csv"
time_column = "t_ms"
time_unit = "ms"
velocity_columns = ["w_fl", "w_fr", "w_rl", "w_rr"]
effort_columns = ["i_fl", "i_fr", "i_rl", "i_rr"]

[imu]
file = "imu.csv"
time_column = "time"
acc_columns = ["ax", "ay", "az"]
includes_gravity = true
gravity_m_s2 = 9.81

[attitude]
file = "imu.csv"
time_column = "time"
roll_column = "roll_deg"
pitch_column = "pitch_deg"
angle_unit = "deg"

[ground_truth]
file = "pose.csv"
time_column = "time"
position_columns = ["x", "y", "z"]
"""


def _rot_x(a):
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _rot_y(a):
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def test_timeseries_csv_matches_an_independent_numpy_computation(tmp_path, capsys):
    rng = np.random.default_rng(7)
    t0 = 1000.0
    # IMU at 100 Hz (gravity in, attitude columns in degrees), wheels at 6.5 Hz in two files (ms), pose at 120 Hz.
    t_imu = t0 + 0.013 + np.arange(0, 41.0, 0.01)
    roll, pitch = 0.05 * np.sin(0.3 * t_imu), 0.08 * np.cos(0.2 * t_imu)
    lin = np.column_stack([0.3 * np.sin(t_imu), 0.1 * np.cos(2 * t_imu), rng.normal(0, 0.2, len(t_imu))])
    grav = np.array([(_rot_y(p) @ _rot_x(r)).T @ [0, 0, 9.81] for r, p in zip(roll, pitch)])  # world z-up into body
    f = lin + grav
    _write_csv(tmp_path / "imu.csv", ["time", "ax", "ay", "az", "roll_deg", "pitch_deg"],
               [t_imu, *f.T, np.degrees(roll), np.degrees(pitch)])
    t_w = t0 + np.arange(0, 41.5, 1 / 6.5)
    w = np.column_stack([2 + np.sin(0.1 * t_w + k) for k in range(4)]) * np.array([1, -1, 1, -1])  # right side negative
    cur = np.abs(rng.normal(1.5, 0.3, (len(t_w), 4)))
    half = len(t_w) // 2
    for name, sl in (("wheels_a.csv", slice(0, half)), ("wheels_b.csv", slice(half, None))):
        _write_csv(tmp_path / name, ["t_ms", "w_fl", "w_fr", "w_rl", "w_rr", "i_fl", "i_fr", "i_rl", "i_rr"],
                   [t_w[sl] * 1000.0, *w[sl].T, *cur[sl].T])
    t_p = t0 - 0.5 + np.arange(0, 42.0, 1 / 120)
    speed = 0.2 * (1 + 0.5 * np.sin(0.05 * t_p))
    pos = np.column_stack([np.cumsum(speed) / 120, 0.1 * np.sin(0.1 * t_p), np.zeros(len(t_p))])
    _write_csv(tmp_path / "pose.csv", ["time", "x", "y", "z"], [t_p, *pos.T])
    (tmp_path / "rover.toml").write_text(CSV_PROFILE)

    rc, text, err = _import(capsys, str(tmp_path), "--rover", str(tmp_path / "rover.toml"), "--out", str(tmp_path / "out"))
    assert rc == 0, err
    got = read_windows_csv(tmp_path / "out" / f"{tmp_path.name}.csv")

    # Independent: integer-ns grid at 50 Hz over the span every sensor covers, np.interp, 100-sample blocks.
    ns = lambda t: np.round(np.asarray(t) * 1e9).astype(np.int64)  # noqa: E731
    start = max(ns(t_imu[0]), ns(t_w[0]), ns(t_p[0]))
    end = min(ns(t_imu[-1]), ns(t_w[-1]), ns(t_p[-1]) - 20_000_000)
    n = (end - start) // 20_000_000 + 1
    g = start + 20_000_000 * np.arange(n + 1)
    x = lambda t: (ns(t) - start).astype(float)  # noqa: E731
    gx = (g - start).astype(float)
    ws = np.interp(gx, x(t_w), np.abs(w).mean(axis=1))
    cu = np.interp(gx, x(t_w), cur.mean(axis=1))
    r_, p_ = np.interp(gx, x(t_imu), roll), np.interp(gx, x(t_imu), pitch)
    acc = np.column_stack([np.interp(gx, x(t_imu), f[:, k]) for k in range(3)])
    acc -= np.array([(_rot_y(p) @ _rot_x(r)).T @ [0, 0, 9.81] for r, p in zip(r_, p_)])
    xyz = np.column_stack([np.interp(gx, x(t_p), pos[:, k]) for k in range(3)])
    step = np.sqrt((np.diff(xyz, axis=0) ** 2).sum(axis=1))
    m = n // 100
    blocks = lambda a: a[: m * 100].reshape(m, 100, *a.shape[1:])  # noqa: E731
    cols = [ws, cu, acc[:, 0], acc[:, 1], acc[:, 2]]
    expect = []
    for c in cols:
        expect += [blocks(c[:n]).mean(axis=1), blocks(c[:n]).std(axis=1)]
    expect += [blocks(p_[:n]).mean(axis=1), blocks(r_[:n]).mean(axis=1)]
    expect = np.column_stack(expect)
    d_act = blocks(step).sum(axis=1)
    d_cmd = blocks(ws[:n] * 0.1 / 50).sum(axis=1)
    slip = np.where(d_cmd >= 0.05, np.clip(1 - d_act / np.where(d_cmd >= 0.05, d_cmd, 1), -1, 1), 0)

    assert len(got) == m == 20
    # the two wheels files follow each other in time: one drive, joined (docs/your_rover.md, one drive per file)
    log = json.loads((tmp_path / "out" / "import_report.json").read_text())["logs"][0]
    assert log["files"] == [tmp_path.name] and "drive" not in log and log["drops"] == {}
    np.testing.assert_allclose(got.features, expect, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.d_actual, d_act, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.d_commanded, d_cmd, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.slip_pct, 100 * slip, rtol=1e-9, atol=1e-9)
    assert np.array_equal(got.label, np.where(np.abs(slip) <= 0.3, 0, np.where(np.abs(slip) <= 0.6, 1, 2)))
    assert got.label.min() != got.label.max() or got.label[0] != 0 or abs(slip).max() > 0.01  # labels not trivially 0


# ---------------------------------------------------------------- bad input


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    root = tmp_path_factory.mktemp("small")
    trace = simulate_traverse("leo", "analog_hall", 9.81, 32.0, seed=11)
    write_traverse_bag(root / "good", trace, "leo", 9.81)
    (root / "leo.toml").write_text(profile_toml("leo", 9.81))
    return root


def _rewrite(src: Path, dst: Path, edit=None, drop_all: bool = False, retype: dict | None = None) -> Path:
    """Copy a bag message by message; `edit(topic, index, msg)` may change a message or return None to drop it;
    `retype` maps a topic to (new message type, function(typestore, msg) -> message of that type)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    retype = retype or {}
    with AnyReader([src], default_typestore=ts) as r, Writer(dst, version=9) as w:
        types = {c.id: retype.get(c.topic, (c.msgtype,))[0] for c in r.connections}
        conns = {c.id: w.add_connection(c.topic, types[c.id], typestore=ts) for c in r.connections}
        count: dict[str, int] = {}
        for c, stamp, raw in r.messages():
            if drop_all:
                continue
            msg = r.deserialize(raw, c.msgtype)
            i = count[c.topic] = count.get(c.topic, -1) + 1
            msg = edit(c.topic, i, msg) if edit else msg
            if c.topic in retype:
                msg = retype[c.topic][1](ts, msg)
            if msg is not None:
                w.write(conns[c.id], stamp, ts.serialize_cdr(msg, types[c.id]))
    return dst


def _as_pose_array(ts, msg):
    return ts.types["geometry_msgs/msg/PoseArray"](msg.header, [msg.pose])


def _as_odometry(ts, msg):
    T = ts.types
    cov = T["geometry_msgs/msg/PoseWithCovariance"](msg.pose, np.zeros(36))
    v = T["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](T["geometry_msgs/msg/Twist"](v, v), np.zeros(36))
    return T["nav_msgs/msg/Odometry"](msg.header, "base_link", cov, twist)


@pytest.mark.parametrize("convert", [_as_pose_array, _as_odometry], ids=["PoseArray", "Odometry"])
def test_ground_truth_as_pose_array_or_odometry(small_bag, tmp_path, convert):
    mtype = "geometry_msgs/msg/PoseArray" if convert is _as_pose_array else "nav_msgs/msg/Odometry"
    bag = _rewrite(small_bag / "good", tmp_path / "gt", retype={"/ground_truth/pose": (mtype, convert)})
    profile = load_profile(small_bag / "leo.toml")
    got, ref = import_log(bag, profile, progress=False), import_log(small_bag / "good", profile, progress=False)
    assert got.windows_kept == ref.windows_kept == 16 and not +got.drops
    np.testing.assert_array_equal(got.segments[0].windows.d_actual, ref.segments[0].windows.d_actual)
    np.testing.assert_array_equal(got.segments[0].windows.label, ref.segments[0].windows.label)


def _profile(root: Path, **replace: str) -> Path:
    text = profile_toml("leo", 9.81)
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    p = root / f"p{abs(hash(tuple(replace.items())))}.toml"
    p.write_text(text)
    return p


def _one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 1
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_good_small_bag_imports_without_drops(small_bag):
    res = import_log(small_bag / "good", load_profile(small_bag / "leo.toml"), progress=False)
    assert res.windows_kept == 16 and not +res.drops


@pytest.mark.parametrize("old, new, needles", [
    # a missing topic: names the key and lists what the bag has
    ('topic = "/ground_truth/pose"', 'topic = "/vicon/rover"', ("ground_truth.topic", "/vicon/rover",
                                                                "/ground_truth/pose (PoseStamped)")),
    # a wrong message type
    ('topic = "/imu/data"', 'topic = "/joint_states"', ("imu.topic", "sensor_msgs/msg/JointState", "sensor_msgs/msg/Imu")),
    # an unknown wheel joint: lists the joints the log has
    ('"wheel_left_1_joint"', '"front_left_wheel"', ("wheels.left_joints", "front_left_wheel", "wheel_left_1_joint")),
    # a typo'd key
    ("includes_gravity = true", "include_gravity = true", ("imu.include_gravity", "unknown key",
                                                           "did you mean 'includes_gravity'")),
], ids=["missing-topic", "wrong-type", "unknown-joint", "typo-key"])
def test_profile_mistakes_are_one_line_errors(small_bag, tmp_path, capsys, old, new, needles):
    p = _profile(tmp_path, **{old: new})
    rc, _, err = _import(capsys, str(small_bag / "good"), "--rover", str(p), "--out", str(tmp_path / "o"))
    _one_line_error(rc, err, *needles)
    assert not (tmp_path / "o").exists()


def test_profile_with_a_typod_section(tmp_path):
    with pytest.raises(ProfileError, match=r"\[improt\] unknown section \(did you mean \[import\]"):
        load_profile(_profile(tmp_path, **{"[import]": "[improt]"}))


def test_gravity_of_the_wrong_place_is_warned_about(small_bag, tmp_path, capsys):
    p = _profile(tmp_path, **{"gravity_m_s2 = 9.81": "gravity_m_s2 = 1.62"})  # an Earth log with the Moon's g
    rc, out, err = _import(capsys, str(small_bag / "good"), "--rover", str(p), "--out", str(tmp_path / "o"))
    assert rc == 0, err
    warning = re.search(r"warning: .*mean acc_z is \+(\d+\.\d+) m/s\^2 .*imu\.gravity_m_s2", out)
    assert warning and 6.0 < float(warning[1]) < 8.2  # 9.81 - 1.62 = 8.19, times cos(pitch) cos(roll)
    rc, _, err = _import(capsys, str(small_bag / "good"), "--rover", str(small_bag / "leo.toml"), "--out",
                         str(tmp_path / "o2"), "--role", "moon")
    _one_line_error(rc, err, "--role 'moon'")


def test_backwards_stamp_is_dropped_and_counted(small_bag, tmp_path):
    def edit(topic, i, msg):
        if topic == "/imu/data" and i == 500:
            msg.header.stamp.sec -= 1  # a stamp from the past
        return msg

    bag = _rewrite(small_bag / "good", tmp_path / "back", edit)
    res = import_log(bag, load_profile(small_bag / "leo.toml"), progress=False)
    assert res.drops["backwards_stamps"] == 1
    assert res.windows_kept == 16


def test_ten_second_gap_cuts_the_log(small_bag, tmp_path, capsys):
    def edit(topic, i, msg):
        return None if 500 <= i < 1000 else msg  # 10 s of silence on every topic (50 Hz)

    bag = _rewrite(small_bag / "good", tmp_path / "gap", edit)
    rc, out, err = _import(capsys, str(bag), "--rover", str(small_bag / "leo.toml"), "--out", str(tmp_path / "o"))
    assert rc == 0, err
    report = json.loads((tmp_path / "o" / "import_report.json").read_text())["logs"][0]
    assert report["drops"]["gaps"] == 4  # one per stream
    # between the segments: from message 498 (the ground truth must reach one sample past a segment) to 1000
    assert report["drops"]["gap_s"] == pytest.approx(10.04, abs=0.001)
    assert report["files"] == ["gap_seg01", "gap_seg02"]
    assert report["windows_kept"] == 5 + 5  # 10 s then 12 s (11.98 s of windows: 5)
    assert "gaps 4" in out
    assert len(load_dataset(tmp_path / "o").files) == 2


def test_nan_in_one_field_is_dropped_and_counted(small_bag, tmp_path):
    def edit(topic, i, msg):
        if topic == "/imu/data" and i == 321:
            msg.linear_acceleration.y = float("nan")
        return msg

    bag = _rewrite(small_bag / "good", tmp_path / "nan", edit)
    res = import_log(bag, load_profile(small_bag / "leo.toml"), progress=False)
    assert res.drops["nonfinite"] == 1 and res.windows_kept == 16


def test_saturated_values_are_dropped_and_counted(small_bag, tmp_path):
    def edit(topic, i, msg):
        if topic == "/imu/data" and i == 50:
            msg.linear_acceleration.x = 160.0  # pegged at the sensor's range
        if topic == "/imu/data" and 700 <= i < 720:
            msg.linear_acceleration.z = 60.0  # within range, beyond the int16 CAN unit (32.767 m/s^2)
        return msg

    bag = _rewrite(small_bag / "good", tmp_path / "sat", edit)
    profile = _profile(tmp_path, **{"gravity_m_s2 = 9.81": "gravity_m_s2 = 9.81\nrange_m_s2 = 156.9"})
    res = import_log(bag, load_profile(profile), progress=False)
    assert res.drops["saturated_messages"] == 1
    assert res.drops["saturated_windows"] == 1
    assert res.windows_kept == 15


def test_windows_with_too_few_samples_are_dropped_and_counted(small_bag, tmp_path):
    def edit(topic, i, msg):
        return None if topic == "/joint_states" and 200 <= i < 300 and i % 25 else msg  # 4 left in window 2

    bag = _rewrite(small_bag / "good", tmp_path / "sparse", edit)
    res = import_log(bag, load_profile(small_bag / "leo.toml"), progress=False)
    assert res.drops["short_windows"] == 1 and res.windows_kept == 15


def test_truncated_bag(small_bag, tmp_path, capsys):
    """Cut before its first whole message: one error line (a bag cut later is salvaged: test_bag_import.py)."""
    mcap = next((small_bag / "good").glob("*.mcap"))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[:3000])
    rc, _, err = _import(capsys, str(cut), "--rover", str(small_bag / "leo.toml"), "--out", str(tmp_path / "o"))
    _one_line_error(rc, err, "cut.mcap", "no messages", "ends inside a chunk")


def test_empty_bag(small_bag, tmp_path, capsys):
    bag = _rewrite(small_bag / "good", tmp_path / "empty", drop_all=True)
    rc, _, err = _import(capsys, str(bag), "--rover", str(small_bag / "leo.toml"), "--out", str(tmp_path / "o"))
    _one_line_error(rc, err, "no messages")


def test_no_ground_truth_gives_unlabelled_windows_and_says_so(small_bag, tmp_path, capsys):
    text = profile_toml("leo", 9.81).split("[ground_truth]")[0] + "[import]\nmax_gap_s = 0.5\n"
    (tmp_path / "nogt.toml").write_text(text)
    rc, out, err = _import(capsys, str(small_bag / "good"), "--rover", str(tmp_path / "nogt.toml"),
                           "--out", str(tmp_path / "o"))
    assert rc == 0, err
    assert "UNLABELLED" in out
    assert (tmp_path / "o" / "good.raw.npz").exists()
    header, *rows = (tmp_path / "o" / "good.unlabelled.csv").read_text().splitlines()
    assert "slip_class" not in header and header.startswith("feat_w_vel_mean,") and len(rows) == 16
    assert json.loads((tmp_path / "o" / "dataset.json").read_text())["files"] == {}


# ---------------------------------------------------------------- roles


def _roles_of_imports(root: Path) -> dict[Path, str]:
    """Each import folder of the round trip and the role its bags have in the simulator's scenario."""
    files = json.loads((root / "sim" / "dataset.json").read_text())["files"].values()
    return {root / "imp" / f["bag"]["profile"]: f["role"] for f in files}


def test_fuse_and_evaluate_run_on_imported_bags_with_roles(mcap_import, tmp_path, capsys):
    root = mcap_import[0]  # one storage is enough here: the round trip shows both give the same windows
    roles = _roles_of_imports(root)
    assert sorted(set(roles.values())) == ["earth", "fleet_hauler", "fleet_scout", "target"]
    (tmp_path / "roles.toml").write_text("".join(f'[[folder]]\npath = "{p}"\nrole = "{r}"\n\n' for p, r in roles.items()))
    assert load_dataset(root / "imp" / "leo_earth.rover.toml").roles == ["unassigned"]
    ds = load_dataset(tmp_path / "roles.toml")
    ds.check_roles()
    fast = ["--epochs", "2", "--no-progress", "--cal-size", "10"]
    assert fleetlab_main(["fuse", "--data", str(tmp_path / "roles.toml"), "--out", str(tmp_path / "fused"),
                          "--generations", "3", "--ants", "20", *fast]) == 0, capsys.readouterr().err
    assert (tmp_path / "fused" / "fused.pt").exists()
    assert fleetlab_main(["evaluate", "--data", str(tmp_path / "roles.toml"), "--runs", "1", "--methods",
                          "acomerge,earth-ft", "--generations", "3", "--ants", "20", "--json",
                          str(tmp_path / "eval.json"), *fast]) == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "eval.json").read_text())


def test_roles_file_mixes_imports_with_other_folders(mcap_import, tmp_path):
    root = mcap_import[0]
    imp = root / "imp" / "leo_earth.rover.toml"
    (tmp_path / "roles.toml").write_text(
        f'[[folder]]\npath = "{imp}"\nrole = "earth"\n\n[[folder]]\npath = "{root / "sim"}"\n')
    ds = load_dataset(tmp_path / "roles.toml")
    sim = load_dataset(root / "sim")
    assert len(ds.files_of("earth")) == len(list(imp.glob("*.csv"))) + len(sim.files_of("earth"))
    assert ds.fleet_roles == sim.fleet_roles and len(ds.table("target")) == len(sim.table("target"))
    (tmp_path / "bad.toml").write_text('[[folder]]\npath = "x"\nrole = "mars"\n')
    with pytest.raises(ValueError, match="role 'mars' is not earth, target or fleet_<rover>"):
        load_dataset(tmp_path / "bad.toml")


# ---------------------------------------------------------------- replay through the C estimator


@pytest.mark.parametrize("link", ["slcan", "cobs"])
def test_emulate_source_replays_an_imported_bag_bit_exact(mcap_import, tmp_path, link):
    from fleetlab.host_tools.emulator import build, default_bundle
    from fleetlab.host_tools.sources import resolve

    root = mcap_import[0]
    folder = root / "imp" / "leo_moon.rover.toml"
    build(default_bundle())
    source = resolve(str(folder), 0, 1.0, None)
    windows = sum(len(read_windows_csv(f)) for f in folder.glob("*.csv"))
    assert source.n_windows == windows > 0
    assert fleetlab_main(["emulate", "--source", str(folder), "--link", link, "--no-progress",
                          "--json", str(tmp_path / "e.json")]) == 0
    s = json.loads((tmp_path / "e.json").read_text())
    assert s["windows"] == s["bit_exact"] == windows
    assert s["mismatches"] == 0 and s["rejected_frames"] == 0


def test_stream_can_source_sends_an_imported_bags_windows(mcap_import, capsys):
    from fleetlab.host_tools.emulator import build, default_bundle

    folder = mcap_import[0] / "imp" / "leo_earth.rover.toml"
    build(default_bundle())
    windows = sum(len(read_windows_csv(f)) for f in folder.glob("*.csv"))
    capsys.readouterr()
    assert fleetlab_main(["stream", "can", "--interface", "virtual", "--source", str(folder), "--quiet"]) == 0
    assert f"received {windows} estimates" in capsys.readouterr().out


def test_roles_file_mixes_an_import_with_the_fleet_to_lab_csvs(mcap_import, real_data_dir, tmp_path):
    imp = mcap_import[0] / "imp" / "leo_earth.rover.toml"
    (tmp_path / "roles.toml").write_text(f'[[folder]]\npath = "{imp}"\nrole = "earth"\n\n'
                                         f'[[folder]]\npath = "{real_data_dir}"\n')
    ds = load_dataset(tmp_path / "roles.toml")
    f2l = load_dataset(real_data_dir)
    ds.check_roles()
    assert ds.roles == f2l.roles and ds.source == "roles file"
    assert len(ds.table("earth")) == len(f2l.table("earth")) + sum(len(read_windows_csv(f)) for f in imp.glob("*.csv"))
    assert len(ds.table("target")) == len(f2l.table("target"))


def test_attitude_from_the_imu_orientation(small_bag, tmp_path):
    """The simulator's Imu carries the same orientation as its Odometry: either source gives the same windows."""
    p = _profile(tmp_path, **{'topic = "/odometry/filtered"': 'topic = "/imu/data"'})
    got = import_log(small_bag / "good", load_profile(p), progress=False)
    ref = import_log(small_bag / "good", load_profile(small_bag / "leo.toml"), progress=False)
    np.testing.assert_array_equal(got.segments[0].windows.features, ref.segments[0].windows.features)
