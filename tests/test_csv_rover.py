"""Issue 44: a real rover's time-series CSV logs all the way (docs/your_rover.md, "A rover with CSV logs only").

A rover that logs one CSV per sensor and drive, without orientation, pose or slip: roll and pitch from the
IMU (`[attitude] source = "imu"`), wheel speeds in m/s, the drives of one folder paired by their suffix,
statistics of unlabelled windows in `data info` and `data compare`, and the smaller checks of the import.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fleetlab.cli import main as fleetlab_main
from fleetlab.data.attitude_bench import traverse_errors
from fleetlab.data.csvio import read_windows_csv
from fleetlab.data.dataset import load_dataset
from fleetlab.data.log_import import gravity_body, import_source
from fleetlab.data.rover_profile import ProfileError, load_profile
from fleetlab.data.simulator.csv_logs import body_rates
from fleetlab.data.simulator.scenario import scenario_traces

REPO = Path(__file__).resolve().parents[1]
SEED, SCALE = 3, 0.05
PITCH, ROLL = 10, 11  # feature columns
WHEEL_FEATURES = slice(0, 4)


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    rc = fleetlab_main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


# ---------------------------------------------------------------- the simulator's traverses as CSV logs


@pytest.fixture(scope="module")
def sim_csv(tmp_path_factory):
    """`simulate --csv-logs`, each profile folder imported with its profile ([attitude] source = "imu")."""
    root = tmp_path_factory.mktemp("csvlogs")
    assert fleetlab_main(["simulate", "--out", str(root / "sim"), "--scale", str(SCALE), "--seed", str(SEED),
                          "--csv-logs", str(root / "logs")]) == 0
    manifest = json.loads((root / "sim" / "dataset.json").read_text())
    folders = sorted({(e["csv_logs"]["folder"], e["csv_logs"]["profile"]) for e in manifest["files"].values()})
    for folder, profile in folders:
        assert "source = \"imu\"" in (root / "logs" / profile).read_text()
        assert fleetlab_main(["data", "import", str(root / "logs" / folder), "--rover", str(root / "logs" / profile),
                              "--out", str(root / "imp" / folder), "--no-progress"]) == 0
    return root, manifest


def test_simulator_csv_logs_import_within_the_measured_attitude_error(sim_csv):
    """Labels, distances and wheel features equal the simulator's; roll and pitch differ from the simulator's own
    windows by the estimator's measured error on the same traverse (the import adds nothing to it), and the
    acceleration features by what that attitude error does to gravity."""
    root, manifest = sim_csv
    measured = {name: (traverse_errors(name, trace, trace.meta["gravity"], "sloped"), trace.meta["gravity"])
                for _, name, trace in scenario_traces(SEED, SCALE)}
    by_place: dict[str, list[np.ndarray]] = {"earth": [], "moon": []}
    for name, entry in manifest["files"].items():
        stem = name[:-4]
        folder = entry["csv_logs"]["folder"]
        sim = read_windows_csv(root / "sim" / name)
        imp = read_windows_csv(root / "imp" / folder / f"{folder}_{stem}.csv")
        err, g = measured[stem]
        assert len(imp) == len(sim) == len(err.window_deg) > 0
        assert np.array_equal(imp.label, sim.label)
        np.testing.assert_allclose(imp.d_actual, sim.d_actual, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(imp.d_commanded, sim.d_commanded, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(imp.features[:, WHEEL_FEATURES], sim.features[:, WHEEL_FEATURES], rtol=1e-9, atol=1e-9)
        delta = imp.features[:, [ROLL, PITCH]] - sim.features[:, [ROLL, PITCH]]
        # the difference is the estimator's own error in that window (within 0.1 degree)
        np.testing.assert_allclose(delta, err.window_signed_rad, atol=math.radians(0.1))
        assert np.all(np.abs(np.degrees(delta)) <= err.window_deg + 0.1)
        # gravity taken out with that attitude: each acceleration mean moves by at most g x the angle errors
        bound = g * np.abs(delta).sum(axis=1) + 0.05
        for col in (4, 6, 8):
            assert np.all(np.abs(imp.features[:, col] - sim.features[:, col]) <= bound)
        by_place["earth" if g > 5 else "moon"].append(np.abs(np.degrees(delta)))
    # the estimator stays within the figures of docs/your_rover.md (Earth about 0.2, Moon about 1 degree)
    earth, moon = np.concatenate(by_place["earth"]), np.concatenate(by_place["moon"])
    assert earth.mean() < 0.5 and np.percentile(earth, 95) < 1.0
    assert moon.mean() < 2.5 and np.percentile(moon, 95) < 6.0


def test_simulator_csv_logs_report_pairs_and_counts(sim_csv):
    root, manifest = sim_csv
    report = json.loads((root / "imp" / "leo_moon" / "import_report.json").read_text())
    stems = sorted(n[:-4] for n, e in manifest["files"].items() if e["csv_logs"]["folder"] == "leo_moon")
    assert [log["drive"] for log in report["logs"]] == stems  # one drive per suffix, their clocks overlap
    assert all(log["drops"] == {} for log in report["logs"])
    assert all(set(log["csv_files"]) == {f"{k}_{log['drive']}.csv" for k in ("imu", "pose", "wheels")}
               for log in report["logs"])
    assert all(0 <= log["attitude"]["untrusted_windows"] <= log["windows_kept"] for log in report["logs"])


def test_bench_attitude_prints_the_figures(capsys):
    rc, out, _ = _run(capsys, "bench", "attitude", "--scale", "0.02", "--seed", "4")
    assert rc == 0
    for place in ("Earth", "Moon"):
        for terrain in ("flat", "sloped"):
            assert re.search(rf"^{place}\s+{terrain}\s+\d+\s+\d+\s+\d+\.\d\d\s+\d+\.\d\d", out, re.M), out


# ---------------------------------------------------------------- a CSV rover: m/s wheels, two drives, no labels


ROVER = """
[rover]
name = "field_rover"

[wheels]
file = "pro_*.csv"
time_column = "time"
velocity_columns = ["v_left", "v_right"]
effort_columns = ["i_left", "i_right"]
velocity_unit = "m/s"

[imu]
file = "imu_*.csv"
time_column = "time"
acc_columns = ["ax", "ay", "az"]
gyro_columns = ["gx", "gy", "gz"]
gyro_unit = "deg/s"
includes_gravity = true
gravity_m_s2 = 9.81

[attitude]
source = "imu"
"""


def _write(path: Path, header: list[str], cols: list[np.ndarray]) -> None:
    rows = np.column_stack(cols)
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")


def _drive(folder: Path, suffix: str, seconds: float, speed: float, seed: int) -> None:
    """One drive: IMU at 100 Hz (gravity in, gyro in deg/s), wheels in m/s and currents at 6.5 Hz; clock from 0."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.01)
    roll, pitch, yaw = 0.05 * np.sin(0.2 * t), 0.1 * np.sin(0.13 * t + seed), 0.1 * t
    rates = body_rates(roll, pitch, yaw, 0.01)
    force = gravity_body(roll, pitch, 9.81) + rng.normal(0, 0.05, (len(t), 3))
    _write(folder / f"imu_{suffix}.csv", ["time", "ax", "ay", "az", "gx", "gy", "gz"],
           [t, *force.T, *np.degrees(rates).T])
    tw = np.arange(0.0, seconds, 1 / 6.5)
    v = speed * (1 + 0.1 * np.sin(0.3 * tw))
    _write(folder / f"pro_{suffix}.csv", ["time", "v_left", "v_right", "i_left", "i_right"],
           [tw, v, -v, 3 + 0 * tw, 3.2 + 0 * tw])


@pytest.fixture
def field_rover(tmp_path):
    folder = tmp_path / "sand"
    folder.mkdir()
    _drive(folder, "00", 80.0, 0.3, 0)  # both drives' clocks start at 0: their times overlap
    _drive(folder, "01", 52.0, 0.5, 1)
    (tmp_path / "field.toml").write_text(ROVER)
    return tmp_path, folder


def test_csv_rover_with_ms_wheels_two_drives_and_no_labels(field_rover, capsys):
    root, folder = field_rover
    rc, out, err = _run(capsys, "data", "import", str(folder), "--rover", str(root / "field.toml"), "--out",
                        str(root / "imp"), "--no-progress")
    assert rc == 0, err
    report = json.loads((root / "imp" / "import_report.json").read_text())["logs"]
    assert [(log["drive"], log["files"], log["windows_kept"]) for log in report] == [
        ("00", ["sand_00"], 39), ("01", ["sand_01"], 25)]
    assert all("backwards_stamps" not in log["drops"] for log in report)
    assert "rim speed in m/s" in out and "high-dynamic" in out
    ds = load_dataset(root / "imp")
    assert not ds.files and [f.path.name for f in ds.unlabelled] == ["sand_00.unlabelled.csv", "sand_01.unlabelled.csv"]
    # commanded distance from the linear wheel speed itself: mean |v| x 2 s
    header, *rows = (root / "imp" / "sand_00.unlabelled.csv").read_text().splitlines()
    d_cmd = np.array([float(r.split(",")[12]) for r in rows])
    assert np.all(np.abs(d_cmd - 0.6) < 0.07)
    # roll and pitch from the IMU: within 0.2 degree of the drive's true attitude in every window
    x = ds.unlabelled[0].features
    t0 = np.arange(len(x)) * 2.0
    true_pitch = np.array([np.mean(0.1 * np.sin(0.13 * np.arange(a, a + 2.0, 0.02))) for a in t0])
    assert np.max(np.abs(np.degrees(x[:, PITCH] - true_pitch))) < 0.2

    rc, out, err = _run(capsys, "data", "info", str(root / "imp"))
    assert rc == 0, err
    assert "64 rows in 2 files" in out and "no labels" in out
    means = {ln.split()[0]: float(ln.split()[1]) for ln in out.splitlines() if ln.startswith("feat_")}
    assert len(means) == 12 and means["feat_w_vel_mean"] == pytest.approx(0.37, abs=0.05)
    assert means["feat_curr_mean"] == pytest.approx(3.1, abs=0.01)

    rc, out, err = _run(capsys, "data", "compare", str(root / "imp"), str(root / "imp"), "--no-learnability")
    assert rc == 0, err
    feature_rows = [ln for ln in out.splitlines() if ln.startswith("feat_")]
    assert len(feature_rows) == 12 and not any("—" in ln for ln in feature_rows)
    assert "no labels" in out


def test_files_of_one_sensor_overlapping_without_a_common_suffix_are_refused(field_rover, capsys):
    root, folder = field_rover
    for k in ("00", "01"):  # no common suffix any more: paired by time, but all four files overlap
        (folder / f"pro_{k}.csv").rename(folder / f"pro_x{k}.csv")
    rc, _, err = _run(capsys, "data", "import", str(folder), "--rover", str(root / "field.toml"), "--out",
                      str(root / "imp"), "--no-progress")
    assert rc == 1 and "overlap in time" in err and "common suffix" in err and len(err.strip().splitlines()) == 1


def test_drives_in_sequence_pair_by_time(field_rover):
    """Without a common suffix, files pair by overlapping time: drives logged one after the other."""
    root, folder = field_rover
    (folder / "imu_00.csv").rename(folder / "imu_a.csv")
    (folder / "pro_00.csv").rename(folder / "pro_p.csv")
    for name, new in (("imu_01.csv", "imu_b.csv"), ("pro_01.csv", "pro_x.csv")):  # an hour later, no common suffix
        lines = (folder / name).read_text().splitlines()
        shifted = [lines[0]] + [",".join([repr(float(ln.split(",")[0]) + 3600.0), *ln.split(",")[1:]]) for ln in lines[1:]]
        (folder / new).write_text("\n".join(shifted) + "\n")
        (folder / name).unlink()
    results = import_source(folder, load_profile(root / "field.toml"), progress=False)
    assert [(r.drive, r.files, r.windows_kept) for r in results] == [
        ("drive01", ["imu_a.csv", "pro_p.csv"], 39), ("drive02", ["imu_b.csv", "pro_x.csv"], 25)]


# ---------------------------------------------------------------- the profile: attitude source, units, scales


def _profile(tmp_path: Path, text: str) -> Path:
    p = tmp_path / f"p{abs(hash(text))}.toml"
    p.write_text(text)
    return p


def test_profile_attitude_and_unit_checks(tmp_path):
    with pytest.raises(ProfileError, match=r'\[attitude\] missing section; logs without orientation: source = "imu"'):
        load_profile(_profile(tmp_path, ROVER.split("[attitude]")[0]))
    with pytest.raises(ProfileError, match=r"rover\.wheel_radius_m: not used with wheels\.velocity_unit = 'm/s'"):
        load_profile(_profile(tmp_path, ROVER.replace('name = "field_rover"', 'name = "r"\nwheel_radius_m = 0.1')))
    with pytest.raises(ProfileError, match=r"unknown unit 'cm/s'; one of rad/s, rpm, deg/s, m/s, km/h .*velocity_scale"):
        load_profile(_profile(tmp_path, ROVER.replace('"m/s"', '"cm/s"')))
    with pytest.raises(ProfileError, match=r"imu\.gyro_columns: missing"):
        load_profile(_profile(tmp_path, ROVER.replace('gyro_columns = ["gx", "gy", "gz"]\n', "")))
    with pytest.raises(ProfileError, match=r"attitude\.roll_column: not used with source = 'imu'"):
        load_profile(_profile(tmp_path, ROVER + 'roll_column = "r"\n'))
    p = load_profile(_profile(tmp_path, ROVER.replace('velocity_unit = "m/s"', 'velocity_unit = "m/s"\nvelocity_scale = 0.01')))
    assert p.velocity_scale == 0.01 and p.metres_per_wheel_speed == 1.0 and p.linear_wheel_speed
    assert load_profile(_profile(tmp_path, ROVER.replace('"m/s"', '"km/h"'))).velocity_scale == pytest.approx(1 / 3.6)
    assert load_profile(_profile(tmp_path, ROVER)).gyro_scale == pytest.approx(math.pi / 180)


def test_level_attitude_warns(field_rover, capsys):
    root, folder = field_rover
    text = ROVER.replace('source = "imu"', 'source = "level"').replace('gyro_columns = ["gx", "gy", "gz"]\n', "")
    (root / "level.toml").write_text(text)
    rc, out, err = _run(capsys, "data", "import", str(folder), "--rover", str(root / "level.toml"), "--out",
                        str(root / "imp"), "--no-progress")
    assert rc == 0, err
    assert re.search(r'warning: .*source = "level": roll and pitch are taken as 0', out)
    ds = load_dataset(root / "imp")
    assert np.all(ds.unlabelled[0].features[:, [PITCH, ROLL]] == 0)


# ---------------------------------------------------------------- issue 44, item 5: the smaller checks


LABELLED = """
[rover]
name = "bench_rover"
wheel_radius_m = 0.1

[wheels]
file = "wheels.csv"
time_column = "time"
velocity_columns = ["w"]
effort_columns = ["i"]

[imu]
file = "imu.csv"
time_column = "time"
acc_columns = ["ax", "ay", "az"]
includes_gravity = true
gravity_m_s2 = 9.81

[attitude]
file = "imu.csv"
time_column = "time"
roll_column = "roll"
pitch_column = "pitch"

[ground_truth]
file = "pose.csv"
time_column = "time"
position_columns = ["x", "y", "z"]
"""


def _bench_rover(folder: Path, current: float = 1.0, edit_imu=None) -> Path:
    """A 40 s labelled drive at 50 Hz on flat ground (imu.csv feeds [imu] and [attitude])."""
    folder.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, 40.0, 0.02)
    n = len(t)
    cols = [t, 0.05 * np.sin(t), np.zeros(n), np.full(n, 9.81), np.zeros(n), np.zeros(n)]
    lines = ["time,ax,ay,az,roll,pitch"] + [",".join(repr(float(c[i])) for c in cols) for i in range(n)]
    if edit_imu:
        edit_imu(lines)
    (folder / "imu.csv").write_text("\n".join(lines) + "\n")
    _write(folder / "wheels.csv", ["time", "w", "i"], [t, np.full(n, 2.0), np.full(n, current)])
    tp = np.arange(0.0, 40.06, 0.02)
    _write(folder / "pose.csv", ["time", "x", "y", "z"], [tp, 0.15 * tp, 0 * tp, 0 * tp])
    return folder


def _import_bench(root: Path, folder: Path, capsys, profile: str = LABELLED):
    (root / "bench.toml").write_text(profile)
    rc, out, err = _run(capsys, "data", "import", str(folder), "--rover", str(root / "bench.toml"), "--out",
                        str(root / "out"), "--no-progress")
    assert rc == 0, err
    return out, json.loads((root / "out" / "import_report.json").read_text())["logs"][0]["drops"]


def test_saturated_windows_name_the_channel(tmp_path, capsys):
    def spike(lines):  # acc_z 40 m/s^2 above g at sample 610 (window 6): beyond the int16 CAN unit (32.767)
        f = lines[611].split(",")
        f[3] = "49.81"
        lines[611] = ",".join(f)

    out, drops = _import_bench(tmp_path, _bench_rover(tmp_path / "log", edit_imu=spike), capsys)
    assert drops["saturated_windows"] == 1 and drops["saturated_windows_acc_z"] == 1
    assert "saturated_windows_acc_z 1" in out


def test_features_far_outside_the_reference_warn_at_import(tmp_path, capsys):
    # 5 mA: far below both references (a rover in range of either one is no unit mistake; above both, the CAN
    # unit of the current saturates first)
    out, _ = _import_bench(tmp_path, _bench_rover(tmp_path / "log", current=0.005), capsys)
    warning = [ln for ln in out.splitlines() if ln.startswith("warning: feat_curr_mean")]
    assert len(warning) == 1 and "the simulator's" in warning[0] and "Fleet-To-Lab's" in warning[0]
    assert "current_per_effort" in warning[0]
    out, _ = _import_bench(tmp_path / "amps", _bench_rover(tmp_path / "amps" / "log", current=25.0), capsys)
    assert not [ln for ln in out.splitlines() if ln.startswith("warning: feat_curr_mean")]  # Fleet-To-Lab's range
    out, _ = _import_bench(tmp_path, _bench_rover(tmp_path / "log2", current=9.0), capsys)  # within 10x of both
    assert "warning: feat_curr_mean" not in out


def test_text_cell_is_non_numeric_and_one_csv_for_two_tables_counts_once(tmp_path, capsys):
    def damage(lines):
        f = lines[101].split(",")
        f[2] = "n/a"  # text in a value cell
        lines[101] = ",".join(f)
        f = lines[202].split(",")
        f[1] = "nan"  # a number written as NaN
        lines[202] = ",".join(f)
        lines[303] = lines[303].replace(lines[303].split(",")[0], "1.0", 1)  # a stamp from the past
        lines[404] = "oops," + lines[404].split(",", 1)[1]  # text in the time column

    out, drops = _import_bench(tmp_path, _bench_rover(tmp_path / "log", edit_imu=damage), capsys)
    # imu.csv feeds [imu] and [attitude]: each bad row is counted once
    assert drops == {"non_numeric": 2, "nonfinite": 1, "backwards_stamps": 1}


def test_help_describes_data_import(capsys):
    with pytest.raises(SystemExit):
        fleetlab_main(["--help"])
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("data "))
    assert "import" in line


def test_your_rover_doc_names_only_files_that_exist():
    """Every Markdown link and every file the guide names (`*.md`, `docs/...`, `tests/...`) exists."""
    text = (REPO / "docs" / "your_rover.md").read_text()
    docs = REPO / "docs"
    missing = []
    for target in re.findall(r"\]\(([^)#\s]+)", text):
        if not target.startswith("http") and not (docs / target).exists():
            missing.append(target)
    for name in re.findall(r"(?<![\w/.(\[])([\w./-]+\.md)\b", text):
        if not ((docs / name).exists() or (REPO / name).exists()):
            missing.append(name)
    for path in re.findall(r"`((?:docs|tests|toolchain|host_tools)/[\w./-]+\.\w+)`", text):
        if not (REPO / path).exists():
            missing.append(path)
    assert not missing, missing


def test_learnability_error_mentions_no_learnability(tmp_path, capsys):
    _import_bench(tmp_path, _bench_rover(tmp_path / "log"), capsys)  # one role, unassigned: nothing to learn on
    rc, _, err = _run(capsys, "data", "compare", str(tmp_path / "out"), str(tmp_path / "out"))
    assert rc == 1 and "learnability needs the roles earth, target" in err and "--no-learnability" in err


def test_roles_file_gives_a_role_to_a_folder_without_dataset_json(tmp_path, capsys):
    _import_bench(tmp_path, _bench_rover(tmp_path / "log"), capsys)
    (tmp_path / "out" / "dataset.json").unlink()  # window CSVs alone, not named like the Fleet-To-Lab files
    (tmp_path / "roles.toml").write_text('[[folder]]\npath = "out"\nrole = "earth"\n')
    ds = load_dataset(tmp_path / "roles.toml")
    assert [f.role for f in ds.files] == ["earth"] and len(ds.table("earth")) == 20
    (tmp_path / "bare.toml").write_text('[[folder]]\npath = "out"\n')
    with pytest.raises(ValueError, match="a roles file that gives the folder a role"):
        load_dataset(tmp_path / "bare.toml")


def test_compare_warns_when_a_feature_is_far_outside_the_reference(tmp_path, capsys):
    _import_bench(tmp_path, _bench_rover(tmp_path / "a", current=0.3), capsys)
    (tmp_path / "out").rename(tmp_path / "ref")
    bad = LABELLED.replace('effort_columns = ["i"]', 'effort_columns = ["i"]\ncurrent_per_effort = 1000.0')
    bad = bad.replace("includes_gravity = true", "includes_gravity = false")  # gravity left in
    _import_bench(tmp_path, _bench_rover(tmp_path / "b", current=0.3), capsys, profile=bad)
    rc, out, err = _run(capsys, "data", "compare", str(tmp_path / "out"), str(tmp_path / "ref"), "--no-learnability")
    assert rc == 0, err
    warnings = {ln.split(":")[1].strip(): ln for ln in out.splitlines() if ln.startswith("warning: feat_")}
    assert "milli" in warnings["feat_curr_mean"] and "current_per_effort" in warnings["feat_curr_mean"]
    assert "gravity" in warnings["feat_acc_z_mean"]
    assert "feat_w_vel_mean" not in warnings


def test_bag_imu_attitude_takes_the_gyro_from_angular_velocity(tmp_path):
    """A bag without orientation: `source = "imu"` reads the Imu messages' angular_velocity as the gyro. The
    rover pitches 0.2 rad every 21 s under heavy vibration: the gyro tracks that, the accelerometer alone
    (a 20 s time constant) could not."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 60.0, 0.01)
    roll, pitch, yaw = 0.05 * np.sin(0.2 * t), 0.2 * np.sin(0.3 * t), 0.05 * t
    rates = body_rates(roll, pitch, yaw, 0.01)
    force = gravity_body(roll, pitch, 9.81) + rng.normal(0, 2.0, (len(t), 3))
    vec, zeros9 = T["geometry_msgs/msg/Vector3"], np.zeros(9)

    def header(i):
        ns = 1_700_000_000_000_000_000 + int(round(t[i] * 1e9))
        return T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), "base")

    with Writer(tmp_path / "bag", version=9) as w:
        imu = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=ts)
        js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for i in range(len(t)):
            stamp = 1_700_000_000_000_000_000 + int(round(t[i] * 1e9))
            w.write(imu, stamp, ts.serialize_cdr(T["sensor_msgs/msg/Imu"](
                header(i), T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0), zeros9, vec(*rates[i]), zeros9,
                vec(*force[i]), zeros9), "sensor_msgs/msg/Imu"))
            if i % 2 == 0:
                w.write(js, stamp, ts.serialize_cdr(T["sensor_msgs/msg/JointState"](
                    header(i), ["l", "r"], np.zeros(2), np.full(2, 3.0), np.full(2, 1.0)), "sensor_msgs/msg/JointState"))
    (tmp_path / "bag.toml").write_text('[rover]\nname = "r"\nwheel_radius_m = 0.1\n[wheels]\ntopic = "/joint_states"\n'
                                       'left_joints = ["l"]\nright_joints = ["r"]\n[imu]\ntopic = "/imu/data"\n'
                                       'includes_gravity = true\ngravity_m_s2 = 9.81\n[attitude]\nsource = "imu"\n')
    (res,) = import_source(tmp_path / "bag", load_profile(tmp_path / "bag.toml"), progress=False)
    x = res.segments[0].windows.features
    true_pitch = np.array([np.mean(0.2 * np.sin(0.3 * np.arange(a, a + 2.0, 0.02))) for a in np.arange(len(x)) * 2.0])
    assert len(x) == 30 and np.max(np.abs(np.degrees(x[:, PITCH] - true_pitch))) < 0.5


def test_a_drive_without_all_its_files_is_left_out_and_counted(field_rover, capsys):
    root, folder = field_rover
    _drive(folder, "02", 30.0, 0.4, 2)
    (folder / "pro_02.csv").unlink()  # the motor controller's file of drive 02 is missing
    rc, out, err = _run(capsys, "data", "import", str(folder), "--rover", str(root / "field.toml"), "--out",
                        str(root / "imp"), "--no-progress")
    assert rc == 0, err
    report = json.loads((root / "imp" / "import_report.json").read_text())["logs"]
    assert [log["drive"] for log in report] == ["00", "01"] and report[0]["drops"] == {"unpaired_files": 1}
    assert "warning: imu_02.csv: no file of every sensor with the same suffix or overlapping in time; left out" in out


@pytest.mark.parametrize("reference", ["Fleet-To-Lab", "the simulator"])
def test_reference_ranges_are_the_reference_datas(reference, request):
    """The import's built-in reference ranges are those of the Fleet-To-Lab files and of the simulator's scenario."""
    from fleetlab.data.reference_ranges import REFERENCE, feature_ranges

    if reference == "Fleet-To-Lab":
        ds = load_dataset(request.getfixturevalue("real_data_dir"))
        x = np.concatenate([f.table.features for f in ds.files])
    else:
        x = np.concatenate([trace.windows().features for _, _, trace in scenario_traces(1, 0.2)])
    got = feature_ranges(x)
    for feature, want in REFERENCE[reference].items():
        np.testing.assert_allclose(got[feature], want, rtol=2e-3, atol=2e-4, err_msg=feature)
