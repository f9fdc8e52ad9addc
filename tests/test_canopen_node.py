"""python `canopen` (the real library) as the master of the C CANopen node, on both buses: a
python-can `virtual` bus with the node bridged in process (ctypes) and `slcan` to the emulator
process over a pseudo-terminal. NMT and heartbeat, SDO reads, TPDO estimates bit-exact with
the torch integer reference, and a model upload by SDO block download, activation, then the
new model's estimates bit-exact."""

from __future__ import annotations

import time
from pathlib import Path

import canopen
import numpy as np
import pytest

from fleetlab.canopen_od import objects as od
from fleetlab.export.bundle import load_bundle
from fleetlab.host_tools.canopen_master import EstimateCollector
from fleetlab.host_tools.canopen_session import CanopenSession, eds_for, stream_telemetry
from fleetlab.host_tools.emulator import EMULATOR_TARGET, find_artifact

from canopen_helpers import EXAMPLE, NODE_ID, REPO, expected_logits, wait_emcy

LINKS = ("inproc", "slcan")


def open_session(link: str, bdir: Path, tmp_path: Path) -> CanopenSession:
    return CanopenSession(link, eds_for(bdir), NODE_ID, lib=find_artifact(bdir, "libslipest_host.so"),
                          emulator=find_artifact(bdir, EMULATOR_TARGET), nvm_file=tmp_path / "nvm.bin")


def heartbeat_reaches(node, state: str, beats: int = 100) -> bool:
    """True once a heartbeat reports `state` (the event an NMT command's effect is read from); the count of
    heartbeats waited for is only a safety net, not a deadline the node must meet."""
    return any(node.nmt.wait_for_heartbeat(2) == state for _ in range(beats))


def run_windows(s: CanopenSession, samples: np.ndarray) -> list:
    s.master.node.tpdo.read()  # the PDO maps, read from the node by SDO
    col = EstimateCollector(s.master.node)
    s.master.node.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    n = stream_telemetry(s, samples, col)
    assert col.wait_for(n, 20), f"{col.count()} of {n} windows"
    return col.estimates


def test_eds_is_loaded_by_canopens_parser_and_matches_the_source(bdir):
    od_py = canopen.import_od(str(eds_for(bdir)), NODE_ID)
    entries = od.objects()
    assert len({(e.index, e.sub) for e in entries}) == len(entries)
    for e in entries:
        obj = od_py[e.index] if e.parent is None else od_py[e.index][e.sub]
        assert obj.data_type == e.dtype, (hex(e.index), e.sub)
    assert od_py[0x1018][2].default == od.PRODUCT_CODE
    assert od_py[0x1800][1].default == 0x180 + NODE_ID  # $NODEID resolved by canopen's parser
    assert od_py[od.IDX_PROGRAM_DATA][1].data_type == canopen.objectdictionary.DOMAIN
    assert 0x2000 not in od_py  # OD 4.0: the image is 0x1F50 sub 1 only


def test_pdo_payloads_are_the_dbc_frames_and_cob_ids_the_predefined_set():
    from fleetlab.host_tools.wire.dbc import codec

    for direction, number, rec in od.PDOS:
        name, frame, fields = od.PDO_RECORDS[rec]
        base = od.pdo_cob_base(direction, number)
        assert base == {("rx", 1): 0x200, ("rx", 2): 0x300, ("rx", 3): 0x400, ("tx", 1): 0x180, ("tx", 2): 0x280,
                        ("tx", 3): 0x380, ("tx", 4): 0x480}[(direction, number)]
        if frame is None:
            continue
        c = codec(frame)
        sizes = [od.TYPE_BYTES[t] for _, t in fields]
        # the PDO maps every signal of the frame, in order; trailing unused DBC bytes are not sent
        assert [n for n, _ in fields] == list(c.signals) and sum(sizes) <= c.length
        signed = [t in od.SIGNED for _, t in fields]
        assert c.fmt.format.strip("<").rstrip("x") == "".join({(1, False): "B", (2, False): "H", (2, True): "h", (4, True): "i",
                                                   (4, False): "I"}[(s, g)] for s, g in zip(sizes, signed))


def test_heartbeats_are_counted_on_the_nodes_own_tick(bdir):
    """The producer heartbeat time, counted against the node's millisecond tick (a simulated clock given to
    slipest_co_tick, no wall time): one heartbeat per second at the default, twenty at 50 ms, evenly spaced."""
    from fleetlab.host_tools.canopen_node import CCanopenNode
    from fleetlab.host_tools.wire.dbc import Frame

    from fleetlab.host_tools.canopen_node import now_ms

    node = CCanopenNode(find_artifact(bdir, "libslipest_host.so"), NODE_ID)  # boots at the tick now_ms()
    # half the 32-bit tick away from boot: the node measures differences modulo 2^32, so any tick works;
    # this one is surely past one period after the boot
    t0 = now_ms() + 2**31

    def heartbeats(start: int, stop: int) -> list[int]:
        return [t for t in range(start, stop) for f in node.tick(t & 0xFFFFFFFF) if f.can_id == 0x700 + NODE_ID]

    first = heartbeats(t0, t0 + 1)  # the first tick after boot is over any period: it sends at once
    assert len(first) == 1
    default = heartbeats(t0 + 1, t0 + 3001)
    assert len(default) == 3 and np.diff(default).tolist() == [od.HEARTBEAT_MS] * 2
    # SDO expedited download of 50 ms into 0x1017:00, answered with the download response
    (ack,) = node.handle(Frame(0x600 + NODE_ID, bytes([0x2B, 0x17, 0x10, 0x00, 50, 0, 0, 0])),
                         (t0 + 3001) & 0xFFFFFFFF)
    assert ack.can_id == 0x580 + NODE_ID and ack.data[0] == 0x60
    fast = heartbeats(t0 + 3001, t0 + 4001)
    assert len(fast) == 20 and set(np.diff(fast).tolist()) == {50}


@pytest.mark.parametrize("link", LINKS)
def test_nmt_heartbeat_and_sdo_reads(bdir, tmp_path, link):
    with open_session(link, bdir, tmp_path) as s:
        node = s.master.node
        s.reset_node()
        assert node.nmt.wait_for_heartbeat(3) == "PRE-OPERATIONAL"
        node.sdo[0x1017].raw = 50
        # the period itself is counted on the node's tick (test_heartbeats_are_counted_on_the_nodes_own_tick)
        assert node.sdo[0x1017].raw == 50
        for _ in range(3):
            node.nmt.wait_for_heartbeat(1)
        for cmd, state in (("OPERATIONAL", "OPERATIONAL"), ("STOPPED", "STOPPED"),
                           ("PRE-OPERATIONAL", "PRE-OPERATIONAL")):
            node.nmt.state = cmd
            assert heartbeat_reaches(node, state)
        node.nmt.state = "STOPPED"
        assert heartbeat_reaches(node, "STOPPED")
        with pytest.raises(canopen.SdoCommunicationError):  # a stopped node has no SDO server
            node.sdo[0x1000].raw
        node.nmt.state = "PRE-OPERATIONAL"
        assert heartbeat_reaches(node, "PRE-OPERATIONAL")
        ident = s.master.identity()
        assert ident == {"vendor_id": od.VENDOR_ID, "product_code": od.PRODUCT_CODE, "revision": od.REVISION,
                         "serial": 1}
        example = load_bundle(EXAMPLE)
        model = s.master.active_model()
        assert model["hash32"] == int(example.content_hash[:8], 16) and model["version"] == 1
        # the built-in model: no slot; its sha256 known at build time (tests/test_canopen_conformance.py reads every
        # object in every boot state)
        assert model["sha256"] == example.content_hash and model["slot"] is None
        for index, sub, code in ((0x3000, 0, 0x06020000), (0x1018, 9, 0x06090011), (0x2000, 0, 0x06020000),
                                 (0x2002, 0, 0x06010001)):
            with pytest.raises(canopen.SdoAbortedError) as e:
                node.sdo.upload(index, sub)
            assert e.value.code == code
        with pytest.raises(canopen.SdoAbortedError) as e:
            node.sdo.download(0x1018, 1, b"\x01\x00\x00\x00")
        assert e.value.code == 0x06010002
        with pytest.raises(canopen.SdoAbortedError) as e:
            node.sdo[od.IDX_ROLLBACK].raw = 1  # the built-in model runs: nothing to roll back to
        assert e.value.code == od.ABORT["STATE"]


@pytest.mark.parametrize("link", LINKS)
def test_tpdo_estimates_are_bit_exact(bdir, tmp_path, link, samples):
    with open_session(link, bdir, tmp_path) as s:
        got = run_windows(s, samples)
        ref = expected_logits(EXAMPLE, samples)
        assert [e.window_counter for e in got] == list(range(len(ref)))
        assert np.array_equal(np.array([e.logits for e in got]), ref)
        assert all(e.n_samples == 100 and e.flags == 0 for e in got)
        c = s.master.counters()
        assert c["windows_done"] == len(ref) and c["frames_rejected"] == 0 and c["rpdo_received"] == 3 * len(samples)


@pytest.mark.parametrize("link", LINKS)
def test_block_download_activate_then_new_model_bit_exact(bdir, tmp_path, link, samples, new_bundle):
    img = (new_bundle / "model.img").read_bytes()
    new = load_bundle(new_bundle)
    with open_session(link, bdir, tmp_path) as s:
        m = s.master
        m.upload(img, block=True)
        st = m.upload_status()
        assert st["state"] == 2 and st["bytes_received"] == len(img)  # READY, not active yet
        assert m.active_model()["version"] == 1
        ready = [sl for sl in m.slots() if sl["state"] == 2]
        assert len(ready) == 1 and ready[0]["version"] == 2 and ready[0]["length"] == len(img)
        m.activate()
        model = m.active_model()
        assert model == {"version": 2, "hash32": int(new.content_hash[:8], 16), "sha256": new.content_hash,
                         "slot": model["slot"]} and model["slot"] in (0, 1)
        got = run_windows(s, samples)
        assert np.array_equal(np.array([e.logits for e in got]), expected_logits(new_bundle, samples))
        assert m.store_counters()["activations"] == 1
        # the same image again is not newer than the active one: refused, counted, EMCY
        with pytest.raises(canopen.SdoAbortedError) as e:
            m.upload(img, block=True)
        assert e.value.code == od.ABORT["STORE"]
        assert m.store_counters()["refused_version"] == 1
        assert wait_emcy(m.node, 0x6300)


def test_new_model_survives_a_power_cycle_inproc(bdir, tmp_path, new_bundle):
    img = (new_bundle / "model.img").read_bytes()
    with open_session("inproc", bdir, tmp_path) as s:
        s.master.upload(img, block=False)  # segmented download this time
        s.master.activate()
        s.power_cycle()  # returns after the boot-up message
        assert s.master.active_model()["version"] == 2


def test_docs_object_dictionary_table_is_the_generated_one():
    from fleetlab.canopen_od.generate import markdown_table

    doc = (REPO / "docs" / "model_update.md").read_text()
    start = doc.index("\n", doc.index("<!-- od-table:start")) + 1
    assert doc[start:doc.index("<!-- od-table:end")] == markdown_table()


def test_python_ram_nvm_keeps_the_strict_nvm_rules() -> None:
    """RamNvm mirrors firmware_c/common/ram_nvm.c: a write onto a sector that is not erased, an unaligned,
    short or out-of-range write is refused (SLIPEST_E_NVM) and changes nothing; after an erase it is taken."""
    import ctypes

    from fleetlab.host_tools.canopen_node import RamNvm
    from fleetlab.host_tools.status_codes import status

    SLIPEST_OK, SLIPEST_E_NVM = status()["SLIPEST_OK"], status()["SLIPEST_E_NVM"]

    nvm = RamNvm(sector_size=64, n_sectors=4)
    buf = (ctypes.c_uint8 * 64)(*([0x5A] * 64))
    assert nvm._write(None, 64, buf, 64) == SLIPEST_OK
    assert nvm._write(None, 64, buf, 64) == SLIPEST_E_NVM  # not erased
    assert nvm._write(None, 65, buf, 64) == SLIPEST_E_NVM  # unaligned
    assert nvm._write(None, 128, buf, 63) == SLIPEST_E_NVM  # short
    assert nvm._write(None, 256, buf, 64) == SLIPEST_E_NVM  # out of range
    assert nvm.writes == 1 and nvm.mem[128:192] == b"\xff" * 64
    assert nvm._erase(None, 64) == SLIPEST_OK and nvm._write(None, 64, buf, 64) == SLIPEST_OK
