"""A rover's own CAN IDs: a copy of the DBC with every frame ID moved by +0x400 drives the
C build (-DSLIPEST_DBC, via `--dbc`) and the host tools, end to end (docs/can_interface.md)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import can
import pytest

from fleetlab.host_tools.wire import dbc

REPO = Path(__file__).resolve().parents[1]
SHIFT = 0x400


def shifted_dbc(text: str, shift: int) -> str:
    """The DBC with every message ID (BO_ lines and their comments) moved by `shift`."""
    move = lambda m: f"{m.group(1)}{int(m.group(2)) + shift}"  # noqa: E731
    return re.sub(r"^((?:CM_ )?BO_ )(\d+)", move, text, flags=re.M)


@pytest.fixture(scope="module")
def rover(tmp_path_factory):
    """(rover DBC path, environment whose fleetlab build dirs live in a temp dir)."""
    tmp = tmp_path_factory.mktemp("rover_dbc")
    path = tmp / "rover.dbc"
    path.write_text(shifted_dbc(dbc.DBC_PATH.read_text(), SHIFT))
    env = dict(os.environ, FLEETLAB_BUILD_ROOT=str(tmp / "build"))
    env.pop("FLEETLAB_DBC", None)
    return path, env


def fleetlab(args: list[str], env: dict[str, str], timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fleetlab.cli", *args], env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_shifted_copy_moves_every_id_and_keeps_the_layout(rover):
    path, _ = rover
    ref = {m.name: m.frame_id for m in dbc.database().messages}
    db = dbc._load(path.resolve())
    assert {m.name: m.frame_id for m in db.messages} == {n: i + SHIFT for n, i in ref.items()}
    dbc.check_layout(db, path.name)  # raises if anything but the IDs changed


def test_emulate_with_the_rover_dbc_is_bit_exact(rover):
    path, env = rover
    out = path.parent / "emulate.json"
    r = fleetlab(["emulate", "--dbc", str(path), "--link", "inproc", "--source", "sim", "--max-windows", "12",
                  "--inject", "unknown_id,wrong_length,duplicated_frame", "--inject-rate", "0.5",
                  "--json", str(out), "--no-progress"], env)
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads(out.read_text())
    assert s["windows"] == 12 and s["bit_exact"] == 12 and s["mismatches"] == 0
    assert s["injected_faults"] > 0 and s["detected_faults"] == s["injected_faults"]
    assert s["dropped_frames"] == 0 and not s["status_problems"]
    # the C codec of that build was generated from the rover DBC
    header = next((path.parent / "build").glob("emulate-*/generated/slipest_dbc.h")).read_text()
    for name in ("TELEM_WHEEL", "SLIP_ESTIMATE", "STATUS_LOSS"):
        want = dbc.frame_id(name) + SHIFT
        assert f"#define SLIPEST_DBC_{name}_FRAME_ID (0x{want:03x}u)" in header


@pytest.mark.parametrize("interface", ["virtual", "slcan"])
def test_frames_on_the_wire_use_the_rover_ids(rover, interface):
    """virtual: the C library in-process on a python-can bus; slcan: the emulator on a pty."""
    path, env = rover
    log = path.parent / f"traffic_{interface}.asc"
    args = ["stream", "can", "--interface", interface, "--dbc", str(path), "--source", "vectors", "--limit", "12",
            "--log", str(log), "--quiet"]
    if interface == "slcan":
        args += ["--channel", "emulator"]
    r = fleetlab(args, env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "received 12 estimates" in r.stdout, r.stdout
    msgs = [m for m in can.LogReader(str(log)) if not m.is_error_frame]
    sent = {m.arbitration_id for m in msgs if not m.is_rx}
    answered = {m.arbitration_id for m in msgs if m.is_rx}
    rover_ids = {m.frame_id for m in dbc._load(path.resolve()).messages}
    old_ids = {m.frame_id for m in dbc.database().messages}
    assert sent | answered <= rover_ids and not (sent | answered) & old_ids
    ids = {n: dbc.frame_id(n) + SHIFT for n in ("FEATURES_0", "CONTROL", "SLIP_ESTIMATE", "SLIP_LOGITS_2",
                                                "STATUS_RX")}
    assert {ids["FEATURES_0"], ids["CONTROL"]} <= sent
    assert {ids["SLIP_ESTIMATE"], ids["SLIP_LOGITS_2"], ids["STATUS_RX"]} <= answered
    # the monitor decodes the same log only with the rover DBC
    r = fleetlab(["monitor", "can", "--replay", str(log), "--dbc", str(path)], env)
    assert r.returncode == 0 and "12 estimates" in r.stdout and "0 unknown" in r.stdout, r.stdout + r.stderr
    r = fleetlab(["monitor", "can", "--replay", str(log)], env)
    assert "0 estimates" in r.stdout and "0 unknown" not in r.stdout, r.stdout


def test_a_dbc_with_another_layout_is_refused_by_host_and_build(rover, tmp_path):
    path, env = rover
    bad = tmp_path / "bad.dbc"
    bad.write_text(path.read_text().replace("SG_ acc_z : 48|16@1- (0.001,0)", "SG_ acc_z : 48|16@1- (0.01,0)"))
    r = fleetlab(["emulate", "--dbc", str(bad), "--link", "inproc", "--max-windows", "1", "--no-progress"], env)
    assert r.returncode == 1 and "TELEM_IMU: layout differs" in r.stderr, r.stderr
    bdir = tmp_path / "build"
    cfg = subprocess.run(["cmake", "-S", str(REPO), "-B", str(bdir), f"-DSLIPEST_DBC={bad}",
                          f"-DPython3_EXECUTABLE={sys.executable}"], capture_output=True, text=True)
    assert cfg.returncode == 0, cfg.stderr
    b = subprocess.run(["cmake", "--build", str(bdir), "--target", "slipest_dbc_gen"], capture_output=True, text=True)
    assert b.returncode != 0 and "TELEM_IMU: layout differs" in b.stdout + b.stderr
    assert not (bdir / "generated" / "slipest_dbc.h").exists()
