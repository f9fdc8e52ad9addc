"""`fleetlab simulate --bag`: each traverse as a rosbag2 (MCAP, or sqlite3), as a ROS 2 collector logs it.

Topics (message types of the Fleet-To-Lab collector), all stamped (and logged) on the sample grid, written
in time order as a recorder writes them:
  /joint_states       sensor_msgs/JointState  one joint per wheel; velocity = that side's measured
                                              speed (rad/s), effort = the motor current (A)
  /imu/data           sensor_msgs/Imu         specific force: linear acceleration WITH gravity
  /odometry/filtered  nav_msgs/Odometry       orientation: the roll and pitch channels taken as REP-103
                                              Z-Y-X angles, heading from the track; position: wheel
                                              odometry (commanded distance), not ground truth
  /ground_truth/pose  geometry_msgs/PoseStamped  true position (motion-capture-like), one sample longer
                                              than the sensors so the last sample's distance is known
Beside the bags, one rover profile per (rover, gravity): `<rover>_<earth|moon>.rover.toml`.
The profile text comes from `profile_toml`, the one source of the example in docs/rover_profiles/.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..contracts import CH
from ..log_import import gravity_body
from ..rover_profile import IMU, JOINT_STATE, ODOMETRY, POSE_STAMPED
from .engine import Trace
from .rovers import GRAVITY_EARTH, ROVERS
from ...errors import InputError

TOPICS = {
    "wheels": ("/joint_states", JOINT_STATE),
    "imu": ("/imu/data", IMU),
    "attitude": ("/odometry/filtered", ODOMETRY),
    "ground_truth": ("/ground_truth/pose", POSE_STAMPED),
}
STORAGES = ("mcap", "sqlite3")
EPOCH_NS = 1_700_000_000 * 1_000_000_000  # stamp of a traverse's first sample


def wheel_joints(rover: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Left and right wheel joint names of a simulated rover."""
    half = ROVERS[rover].n_wheels // 2
    return (tuple(f"wheel_left_{k + 1}_joint" for k in range(half)),
            tuple(f"wheel_right_{k + 1}_joint" for k in range(ROVERS[rover].n_wheels - half)))


def place(gravity: float) -> str:
    return "earth" if abs(gravity - GRAVITY_EARTH) < 1e-9 else "moon"


def profile_name(rover: str, gravity: float) -> str:
    return f"{rover}_{place(gravity)}.rover.toml"


def _names(xs: tuple[str, ...]) -> str:
    return "[" + ", ".join(f'"{x}"' for x in xs) + "]"


def profile_toml(rover: str, gravity: float) -> str:
    """The rover profile of the simulator's bags for one rover and gravity."""
    left, right = wheel_joints(rover)
    return f"""# Rover profile: fleetlab's simulated {rover} rover ({place(gravity)}, g = {gravity} m/s^2), as
# `fleetlab simulate --bag` logs it. Reference: docs/your_rover.md.

[rover]
name = "{rover}"
wheel_radius_m = {ROVERS[rover].wheel_radius_m}

[wheels]
topic = "{TOPICS['wheels'][0]}"            # sensor_msgs/JointState
left_joints = {_names(left)}
right_joints = {_names(right)}
velocity_unit = "rad/s"
current_per_effort = 1.0               # the effort field carries motor current in A

[imu]
topic = "{TOPICS['imu'][0]}"               # sensor_msgs/Imu
includes_gravity = true                 # raw specific force: gravity is removed with [attitude]
gravity_m_s2 = {gravity}

[attitude]
topic = "{TOPICS['attitude'][0]}"   # nav_msgs/Odometry orientation -> roll, pitch

[ground_truth]
topic = "{TOPICS['ground_truth'][0]}"   # geometry_msgs/PoseStamped (motion capture)

[import]
max_gap_s = 0.5
"""


def _quaternions(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(n, 4) x, y, z, w of the REP-103 Z-Y-X rotation yaw, pitch, roll."""
    cr, sr, cp, sp, cy, sy = (f(a / 2) for a in (roll, pitch, yaw) for f in (np.cos, np.sin))
    return np.column_stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


def _heading(trace: Trace) -> np.ndarray:
    """Direction of travel from the true track (held where the rover does not move)."""
    dx, dy = np.gradient(trace.truth["x"]), np.gradient(trace.truth["y"])
    h = np.arctan2(dy, dx)
    moving = np.hypot(dx, dy) > 0
    idx = np.maximum.accumulate(np.where(moving, np.arange(len(h)), 0))
    return np.where(moving[idx], h[idx], 0.0)


def write_traverse_bag(path: Path, trace: Trace, rover: str, gravity: float, storage: str = "mcap") -> Path:
    """Write one traverse as a rosbag2 folder `path` (replaced if it exists)."""
    import shutil

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    if storage not in STORAGES:
        raise InputError(f"bag storage must be one of {', '.join(STORAGES)}, got {storage!r}")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Vec, Point, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
    Pose = T["geometry_msgs/msg/Pose"]
    s, n, dt_ns = trace.samples, len(trace.samples), int(round(1e9 / trace.rate_hz))
    stamps = EPOCH_NS + np.arange(n + 1, dtype=np.int64) * dt_ns
    left, right = wheel_joints(rover)
    yaw = _heading(trace)
    quat = _quaternions(s[:, CH["roll"]], s[:, CH["pitch"]], yaw)
    acc = s[:, [CH["acc_x"], CH["acc_y"], CH["acc_z"]]] + gravity_body(s[:, CH["roll"]], s[:, CH["pitch"]], gravity)
    # The true track, rebuilt from the simulator's per-sample distance along the heading: its
    # step lengths are exactly the path length the simulator's labels use.
    pos = np.zeros((n + 1, 3))
    pos[1:, 0] = np.cumsum(trace.d_actual_step * np.cos(yaw))
    pos[1:, 1] = np.cumsum(trace.d_actual_step * np.sin(yaw))
    # Wheel odometry dead-reckons the commanded distance: a position to take attitude from, never
    # ground truth (slip measured against it would be zero by construction).
    odom = np.zeros((n, 3))
    odom[1:, 0] = np.cumsum(trace.d_cmd_step * np.cos(yaw))[:-1]
    odom[1:, 1] = np.cumsum(trace.d_cmd_step * np.sin(yaw))[:-1]
    zeros9, zeros36 = np.zeros(9), np.zeros(36)

    def header(i: int, frame: str):
        return Header(Time(sec=int(stamps[i] // 1_000_000_000), nanosec=int(stamps[i] % 1_000_000_000)), frame)

    path = Path(path)
    if path.exists():
        shutil.rmtree(path)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conn = {k: w.add_connection(topic, mtype, typestore=ts) for k, (topic, mtype) in TOPICS.items()}

        def put(key: str, i: int, msg) -> None:
            w.write(conn[key], int(stamps[i]), ts.serialize_cdr(msg, TOPICS[key][1]))

        def truth(i: int):
            return T[POSE_STAMPED](header(i, "map"), Pose(Point(*pos[i]), Quat(0.0, 0.0, 0.0, 1.0)))

        # in time order, as a recorder writes what it receives: a bag cut short holds every topic up to the cut
        names = list(left + right)
        for i in range(n):
            vel = np.array([trace.truth["wheel_left"][i]] * len(left) + [trace.truth["wheel_right"][i]] * len(right))
            put("wheels", i, T[JOINT_STATE](header(i, "base_link"), names, np.zeros(len(names)), vel,
                                                             np.full(len(names), s[i, CH["motor_current"]])))
            q = Quat(*quat[i])
            put("imu", i, T[IMU](header(i, "imu_link"), q, zeros9, Vec(0.0, 0.0, 0.0), zeros9,
                                                   Vec(*acc[i]), zeros9))
            odom_pose = T["geometry_msgs/msg/PoseWithCovariance"](Pose(Point(*odom[i]), q), zeros36)
            twist = T["geometry_msgs/msg/TwistWithCovariance"](
                T["geometry_msgs/msg/Twist"](Vec(0.0, 0.0, 0.0), Vec(0.0, 0.0, 0.0)), zeros36)
            put("attitude", i, T[ODOMETRY](header(i, "odom"), "base_link", odom_pose, twist))
            put("ground_truth", i, truth(i))
        put("ground_truth", n, truth(n))
    return path
