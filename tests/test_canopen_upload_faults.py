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

from fleetlab.canopen_od import objects as od
from fleetlab.host_tools.canopen_master import EstimateCollector
from fleetlab.host_tools.canopen_session import CanopenSession, eds_for, stream_telemetry
from fleetlab.host_tools.emulator import EMULATOR_TARGET, find_artifact
from fleetlab.host_tools.verify.upload_faults import (UPLOAD_EFFECTS, UPLOAD_FAULTS, UPLOAD_WIRE_FAULTS,
                                                      SdoFaultBus, faulty_image)

from canopen_helpers import EXAMPLE, NODE_ID, expected_logits, wait_emcy


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
        m.clear()  # CiA 302-3 clear, a PRE-OPERATIONAL service: before the telemetry streams
        m.node.nmt.state = "OPERATIONAL"
        time.sleep(0.05)
        sent: list[int] = []
        streamer = threading.Thread(target=lambda: sent.append(stream_telemetry(s, samples, col)))
        streamer.start()
        assert col.wait_for(2, 10)  # the upload starts while windows are flowing
        error: Exception | None = None
        try:
            m.upload(faulty_image(kind, new_img), block=True, clear=False)
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
        m.node.nmt.state = "PRE-OPERATIONAL"
        if not effect.fails:
            m.clear()  # 0x1F51 = 3: the validated download is dropped
        assert m.upload_status()["state"] == 0  # nothing validated: nothing a start could activate
        m.activate()  # the CiA 302-3 start with nothing new downloaded: the running model starts again
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


SIGN_KEY = bytes(range(7, 39))


def _one_defect(kind: str, good: bytes, bad: bytes) -> None:
    """bad is good with exactly the defect `kind` names and nothing else: whatever check a reader runs first,
    it can only refuse the image for that one reason."""
    from fleetlab.export import image_layout

    n_body = image_layout.body_size(good)
    if kind == "corrupt_image":  # one payload bit, CRC left as it was
        diff = [i for i, (a, b) in enumerate(zip(good, bad)) if a != b]
        assert len(bad) == len(good) and len(diff) == 1 and image_layout.CURRENT.header_size <= diff[0] < n_body
        assert bin(good[diff[0]] ^ bad[diff[0]]).count("1") == 1
    elif kind == "wrong_arch":  # another architecture id under a CRC that matches; nothing else changed
        fields = image_layout.header_fields(bad)
        assert fields["arch"] != image_layout.header_fields(good)["arch"]
        assert image_layout.reseal(bad) == bad, "the CRC does not cover the edited header"
        assert image_layout.patch_header(bad, arch=image_layout.header_fields(good)["arch"]) == good
    elif kind == "truncated":
        assert len(bad) < len(good) and good.startswith(bad)
    else:  # the bytes are unchanged: the node refuses the version, or a wire fault acts on the frames
        assert bad == good


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
@pytest.mark.parametrize("kind", UPLOAD_FAULTS)
def test_every_upload_fault_leaves_exactly_its_defect(new_bundle, kind, signed) -> None:
    """Every upload fault applied to an unsigned and to an HMAC-signed image changes only what it names
    (on a signed image the CRC sits 32 bytes further from the end: a fault that reseals it must find it)."""
    from fleetlab.export.model_image import read_image, sign_image

    good = (new_bundle / "model.img").read_bytes()
    if signed:
        good = sign_image(good, SIGN_KEY)
    bad = faulty_image(kind, good)
    _one_defect(kind, good, bad)
    if kind in UPLOAD_WIRE_FAULTS or kind == "stale_version":
        read_image(bad, hmac_key=SIGN_KEY if signed else None)  # still a valid image
