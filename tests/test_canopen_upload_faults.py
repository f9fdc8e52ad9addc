"""Model uploads with faults, through python `canopen` to the C node: every fault ends with the old
model active, is reported by the node (SDO abort code, EMCY, counter; or, where the block protocol
repairs it, the count of sequence errors), and no window is lost: telemetry streams during the
upload and every window's estimate arrives, bit-exact with the old model."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import canopen
import numpy as np
import pytest

from fleetlab.export.bundle import load_bundle
from fleetlab.host_tools.canopen_master import EstimateCollector
from fleetlab.host_tools.canopen_session import CanopenSession, eds_for, stream_telemetry
from fleetlab.host_tools.emulator import EMULATOR_TARGET, find_artifact
from fleetlab.host_tools.verify.faults import (UPLOAD_EFFECTS, UPLOAD_FAULTS, UPLOAD_WIRE_FAULTS, SdoFaultBus,
                                               faulty_image)

from test_canopen_node import EXAMPLE, NODE_ID, bdir, expected_logits, new_bundle, samples, wait_emcy  # noqa: F401


def counters(s: CanopenSession, which: str) -> dict[str, int]:
    return s.master.store_counters() if which == "store" else s.master.counters()


# every kind on the in-process bus; on slcan (the emulator process) one of each family
CASES = [(k, "inproc") for k in UPLOAD_FAULTS] + [(k, "slcan") for k in
                                                  ("wrong_arch", "drop_segment", "corrupt_segment", "abort_midway")]


@pytest.mark.parametrize(("kind", "link"), CASES)
def test_upload_fault_keeps_the_old_model_and_every_window(bdir, tmp_path, samples, new_bundle, kind, link):
    effect = UPLOAD_EFFECTS[kind]
    new_img = (new_bundle / "model.img").read_bytes()
    wrap = (lambda bus: SdoFaultBus(bus, NODE_ID, kind)) if kind in UPLOAD_WIRE_FAULTS else None
    with CanopenSession(link, eds_for(bdir), NODE_ID, lib=find_artifact(bdir, "libslipest_host.so"),
                        emulator=find_artifact(bdir, EMULATOR_TARGET), nvm_file=tmp_path / "nvm.bin",
                        wrap_bus=wrap) as s:
        m = s.master
        old_bundle = EXAMPLE
        if kind == "stale_version":  # make version 2 the active one; version 1 is then stale
            m.upload(new_img)
            m.activate()
            old_bundle, new_img = new_bundle, (EXAMPLE / "model.img").read_bytes()
        old = m.active_model()
        before = counters(s, effect.counter[0])
        m.node.tpdo.read()
        col = EstimateCollector(m.node)
        m.node.nmt.state = "OPERATIONAL"
        time.sleep(0.05)
        sent: list[int] = []
        streamer = threading.Thread(target=lambda: sent.append(stream_telemetry(s, samples, col)))
        streamer.start()
        assert col.wait_for(2, 10)  # the upload starts while windows are flowing
        error: Exception | None = None
        try:
            m.upload(faulty_image(kind, new_img), block=True)
        except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as e:
            error = e
        streamer.join(30)
        assert sent and col.wait_for(sent[0], 20), f"windows lost: {col.count()} of {sent}"
        got = np.array([e.logits for e in col.estimates])
        assert [e.window_counter for e in col.estimates] == list(range(sent[0]))
        assert np.array_equal(got, expected_logits(old_bundle, samples)), "an estimate did not come from the old model"
        if effect.fails:
            assert error is not None, "the faulty upload was accepted"
            if effect.abort_code is not None:
                assert isinstance(error, canopen.SdoAbortedError) and error.code == effect.abort_code, error
        else:
            assert error is None, error
            assert m.upload_status()["state"] == 2  # repaired by the protocol: READY, every check passed
        if effect.emcy is not None:
            assert wait_emcy(m.node, effect.emcy)
        time.sleep(0.05)
        after = counters(s, effect.counter[0])
        assert after[effect.counter[1]] > before[effect.counter[1]], (effect.counter, before, after)
        assert m.active_model() == old  # the old model is still the active one
        with pytest.raises(canopen.SdoAbortedError):
            if effect.fails:
                m.activate()  # nothing valid to activate
            else:
                m.abort_upload()
                m.activate()
        assert m.active_model() == old


@pytest.fixture(scope="module")
def keyed(tmp_path_factory) -> tuple[Path, bytes]:
    """A node built with an HMAC key provisioned (-DSLIPEST_HMAC_KEY_FILE): its build dir and the key."""
    from fleetlab.host_tools.firmware.build import cmake_build

    root = tmp_path_factory.mktemp("keyed")
    key = bytes(range(40, 72))
    (root / "key.bin").write_bytes(key)
    bdir = cmake_build(root / "build", EXAMPLE, options={"SLIPEST_HMAC_KEY_FILE": str(root / "key.bin")}, jobs=2,
                       targets=(EMULATOR_TARGET,))
    return bdir, key


@pytest.mark.parametrize("kind", ["unsigned_image", "wrong_hmac"])
def test_keyed_node_refuses_images_without_the_right_tag_then_takes_a_signed_one(keyed, tmp_path, new_bundle, kind):
    from fleetlab.export.model_image import sign_image

    bdir, key = keyed
    effect = UPLOAD_EFFECTS[kind]
    img = (new_bundle / "model.img").read_bytes()
    with CanopenSession("slcan", eds_for(bdir), NODE_ID, emulator=find_artifact(bdir, EMULATOR_TARGET),
                        nvm_file=tmp_path / "nvm.bin") as s:
        m = s.master
        old = m.active_model()
        with pytest.raises(canopen.SdoAbortedError) as e:
            m.upload(faulty_image(kind, img))
        assert e.value.code == effect.abort_code and wait_emcy(m.node, effect.emcy)
        assert m.store_counters()["refused_hmac"] == 1 and m.active_model() == old
        m.upload(sign_image(img, key))
        m.activate()
        assert m.active_model()["version"] == 2
