"""The committed golden frames of the CANopen profile (firmware_c/tests/golden/co_frames_example.txt), decoded
without the C code that wrote them. Every CPU target's frames are compared with this file (ctest
co_frames_golden_<cpu>), so it must itself be right: here the python `canopen` package reads the project's EDS
(generated from canopen_od/objects.py), its RPDO maps decode the telemetry the node received, its TPDO maps
the estimates the node sent, its NMT master the heartbeats and its EMCY consumer the emergency; the estimates
are compared with the torch integer reference (fleetlab.export.intref) for the decoded telemetry.

Each line is "<tick ms> <rx|tx> <id> <dlc> <data hex> | <SLCAN text> | <COBS packet hex>" (one frame, three
agreeing encodings; firmware_c/target/co_frames.c writes it on the node's own simulated millisecond tick)."""

from __future__ import annotations

import canopen
import numpy as np
import pytest

from fleetlab.canopen_od import generate
from fleetlab.canopen_od import objects as od
from fleetlab.data.features_int import featurise_int
from fleetlab.export.bundle import load_bundle
from fleetlab.export.intref import q_logits_of
from fleetlab.host_tools.status_codes import status
from fleetlab.paths import repo_root

from golden_node_frames import (
    NO_FLOAT_CLASS,
    assert_windows_equal_the_reference,
    golden_line,
    golden_lines,
    node_frames_stream,
)

REPO = repo_root()
GOLDEN = REPO / "firmware_c" / "tests" / "golden" / "co_frames_example.txt"
BUNDLE = REPO / "firmware_c" / "bundles" / "example"
NODE_ID = 5
ERR_COMMUNICATION = 0x10  # CiA 301 error register, bit 4
# the RPDO records in DBC channel order (the telemetry columns of node_frames_stream)
CHANNELS = (("Telemetry wheel", ("wheel_speed", "motor_current")), ("Telemetry IMU", ("acc_x", "acc_y", "acc_z")),
            ("Telemetry attitude", ("roll", "pitch")))


class Decoded:
    """What a python-canopen master makes of the golden session: the PDOs by mapped record (with the tick of
    each), the node's heartbeats (tick, NMT state), its EMCY log, and which COB-IDs went which way."""

    def __init__(self, eds, path=GOLDEN):
        lines, self.count = golden_lines(path)
        self.n_lines = len(lines)
        net = canopen.Network()  # no bus: the golden lines are fed to it with notify()
        self.node = canopen.RemoteNode(NODE_ID, str(eds))
        net.add_node(self.node)
        self.pdos: dict[str, list[tuple[int, dict]]] = {}
        self.heartbeats: list[tuple[int, str]] = []
        self.short_pdos: list[tuple[int, str, int]] = []
        self.tick = 0
        self.cob_ids: dict[str, set[int]] = {"rx": set(), "tx": set()}
        for maps in (self.node.rpdo, self.node.tpdo):
            maps.read(from_od=True)  # the maps as the EDS defines them
            for m in maps.map.values():
                if m.cob_id:
                    m.add_callback(self._pdo)
        self.node.nmt.add_heartbeat_callback(
            lambda state: self.heartbeats.append((self.tick, canopen.nmt.NMT_STATES[state])))
        for lead, can_id, data in lines:
            tick, direction = lead
            assert direction in ("rx", "tx") and int(tick) >= self.tick, lead
            self.tick = int(tick)
            self.cob_ids[direction].add(can_id)
            net.notify(can_id, bytearray(data), self.tick / 1000)

    def _pdo(self, m) -> None:
        record = m[0].name.split(".")[0]
        try:
            values = {v.name.split(".")[1]: v.raw for v in m}
        except canopen.objectdictionary.ObjectDictionaryError:  # shorter than its map: canopen will not decode it
            self.short_pdos.append((self.tick, record, len(m.data)))
            return
        self.pdos.setdefault(record, []).append((self.tick, values))

    def telemetry(self) -> tuple[np.ndarray, np.ndarray]:
        """The received samples (columns in DBC order) and their sample counters, from the three RPDOs."""
        cols, counters = [], []
        for record, names in CHANNELS:
            rows = [values for _, values in self.pdos[record]]
            counters.append([r["sample_counter"] for r in rows])
            cols += [[r[name] for r in rows] for name in names]
        assert counters[0] == counters[1] == counters[2]
        return np.array(cols, dtype=np.int16).T, np.array(counters[0])

    def estimates(self) -> list[dict]:
        """The three estimate TPDOs of each window, joined on the window counter."""
        est = [dict(v, tick=t) for t, v in self.pdos["Slip estimate"]]
        l01, l2 = self.pdos["Slip logits 01"], self.pdos["Slip logit 2"]
        assert len(est) == len(l01) == len(l2)
        for e, (t1, a), (t2, b) in zip(est, l01, l2):
            assert e["tick"] == t1 == t2 and b["window_counter"] == e["window_counter"]
            e["logits"] = [a["logit_0"], a["logit_1"], b["logit_2"]]
        return est


@pytest.fixture(scope="module")
def eds(tmp_path_factory):
    path = tmp_path_factory.mktemp("eds") / "slipest.eds"
    path.write_text(generate.eds_text())
    return path


@pytest.fixture(scope="module")
def decoded(eds):
    return Decoded(eds)


def test_every_line_is_one_frame_and_every_frame_is_decoded(decoded):
    assert decoded.count == decoded.n_lines > 3000
    # received: NMT and the three RPDOs; sent: TPDO1..4, EMCY and heartbeat (the predefined connection set)
    assert decoded.cob_ids == {"rx": {0, 0x205, 0x305, 0x405}, "tx": {0x185, 0x285, 0x385, 0x485, 0x085, 0x705}}
    received = sum(len(decoded.pdos[r]) for r, _ in CHANNELS)
    sent = sum(len(v) for k, v in decoded.pdos.items() if not k.startswith("Telemetry"))
    # the lines besides the PDOs: boot-up + heartbeats, the EMCY, two NMT commands, the short RPDO
    assert (received + sent + len(decoded.heartbeats) + len(decoded.node.emcy.log) + 2 + len(decoded.short_pdos)
            == decoded.n_lines)


def test_rpdos_carry_node_frames_telemetry(decoded):
    samples, counters = decoded.telemetry()
    assert counters.tolist() == list(range(1050))
    assert np.array_equal(samples, node_frames_stream(1050))
    ticks = [t for t, _ in decoded.pdos["Telemetry IMU"]]
    assert np.diff(ticks).tolist() == [10] * 1049  # one sample every 10 ms of the node's tick
    # and one RPDO1 four bytes long, which canopen's map (six bytes) does not decode either
    assert [(r, n) for _, r, n in decoded.short_pdos] == [("Telemetry wheel", 4)]


def test_estimate_tpdos_equal_the_torch_integer_reference(decoded):
    est = decoded.estimates()
    ref = assert_windows_equal_the_reference(est, *decoded.telemetry())
    assert len(est) == 10
    assert {e["slip_class_f32"] for e in est} == {NO_FLOAT_CLASS}
    # each window's TPDOs go out on the tick of the sample that closes it
    imu_ticks = [t for t, _ in decoded.pdos["Telemetry IMU"]]
    closing = np.cumsum(ref.n_samples) - 1
    assert [e["tick"] for e in est] == [imu_ticks[k] for k in closing]


def test_model_status_tpdo_names_the_bundles_model(decoded):
    manifest = load_bundle(BUNDLE).manifest
    status_tpdos = decoded.pdos["Model status"]
    assert [v for _, v in status_tpdos] == [{"model_hash32": int(manifest["content_hash"][:8], 16),
                                              "model_version": manifest["model_version"]}]
    # TPDO4 goes out with the tenth window's estimate
    assert status_tpdos[0][0] == decoded.pdos["Slip estimate"][9][0]


def test_heartbeats_report_each_nmt_state_on_the_nodes_tick(decoded):
    beats = decoded.heartbeats
    period = decoded.node.object_dictionary[0x1017].default
    assert period == od.HEARTBEAT_MS
    assert beats[0] == (0, "INITIALISING")  # the boot-up message
    states = [s for _, s in beats[1:]]
    assert states == ["PRE-OPERATIONAL"] * 2 + ["OPERATIONAL"] * 10 + ["STOPPED"]
    ticks = [t for t, _ in beats]
    assert np.diff(ticks[:-1]).tolist() == [period] * 12
    # the heartbeat after NMT stop comes on the node's first tick at least a period after the last one
    assert period <= ticks[-1] - ticks[-2] < period + 10
    assert decoded.node.nmt.state == "STOPPED"


def test_the_short_rpdo_gives_one_pdo_length_emcy(decoded):
    (emcy,) = decoded.node.emcy.log
    assert emcy.code == od.EMCY["PDO_LENGTH"]
    assert emcy.register & ERR_COMMUNICATION
    assert int.from_bytes(emcy.data[:1], "little", signed=True) == status()["SLIPEST_E_LENGTH"]
    assert round(emcy.timestamp * 1000) == decoded.short_pdos[0][0]  # answered on the short RPDO's tick


def test_a_wrong_golden_is_caught(eds, tmp_path):
    """The decoding can fail: one logit byte changed (in all three encodings of its line) is a logit the
    reference does not give."""
    from fleetlab.host_tools.wire.dbc import Frame

    lines = GOLDEN.read_text().splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.split()[1:3] == ["tx", str(0x280 + NODE_ID)])
    tick, direction, can_id, _, data = lines[at].split("|")[0].split()
    f = Frame(int(can_id), bytes([bytes.fromhex(data)[0] ^ 1]) + bytes.fromhex(data)[1:])
    bad = tmp_path / "golden.txt"
    bad.write_text("".join(lines[:at] + [golden_line(f, f"{tick} {direction} ")] + lines[at + 1:]))
    got = Decoded(eds, bad).estimates()[0]["logits"]
    want = decoded_reference_logits()[0]
    assert got != want and got[1:] == want[1:]


def decoded_reference_logits() -> list[list[int]]:
    ref = featurise_int(node_frames_stream(1050), np.arange(1050))
    return q_logits_of(load_bundle(BUNDLE).qparams, ref.features).tolist()
