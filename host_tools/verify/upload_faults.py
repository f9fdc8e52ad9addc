"""Upload faults: model uploads over CANopen (SDO block download to the CiA 302-3 program data, DOMAIN 0x1F50
sub 1) with one fault each.

Image faults change the bytes the master sends (through the one image description,
export/image_layout.py, so they work on unsigned and signed images alike); wire faults change the
SDO request frames on their way to the node (`SdoFaultBus`). Every kind ends with the old model
active (activation is a separate, explicit command) and is reported by the node: an SDO abort
code, an EMCY and a counter, or, where the block protocol repairs the fault itself, the node's
count of sequence errors and an image that still passes every check.
"""

from __future__ import annotations

from dataclasses import dataclass

import can

from fleetlab.canopen_od.objects import ABORT, EMCY
from fleetlab.export import image_layout
from fleetlab.export.model_image import sign_image
from fleetlab.errors import InputError

UPLOAD_IMAGE_FAULTS = ("corrupt_image", "wrong_arch", "truncated", "stale_version")
UPLOAD_WIRE_FAULTS = ("drop_segment", "duplicate_segment", "reorder_segments", "corrupt_segment", "wrong_block_crc",
                      "abort_midway")
UPLOAD_FAULTS = UPLOAD_IMAGE_FAULTS + UPLOAD_WIRE_FAULTS
# only on a node built with an HMAC key (cmake -DSLIPEST_HMAC_KEY_FILE=...): the image is unsigned, or
# signed under another key
UPLOAD_KEYED_FAULTS = ("unsigned_image", "wrong_hmac")


@dataclass(frozen=True)
class UploadEffect:
    fails: bool  # the transfer must fail (else the protocol repairs the fault)
    abort_code: int | None  # SDO abort code the node sends (None: none, e.g. the master aborted)
    emcy: int | None  # EMCY error code the node must send
    counter: tuple[str, str]  # ("store" | "node", counter name) that must grow by one or more


UPLOAD_EFFECTS: dict[str, UploadEffect] = {
    "corrupt_image": UploadEffect(True, ABORT["STORE"], EMCY["DATA_SET"], ("store", "refused_crc")),
    "wrong_arch": UploadEffect(True, ABORT["STORE"], EMCY["DATA_SET"], ("store", "refused_arch")),
    "truncated": UploadEffect(True, ABORT["LENGTH"], EMCY["DATA_SET"], ("store", "refused_length")),
    "stale_version": UploadEffect(True, ABORT["STORE"], EMCY["DATA_SET"], ("store", "refused_version")),
    "unsigned_image": UploadEffect(True, ABORT["STORE"], EMCY["DATA_SET"], ("store", "refused_hmac")),
    "wrong_hmac": UploadEffect(True, ABORT["STORE"], EMCY["DATA_SET"], ("store", "refused_hmac")),
    # the block protocol repeats what a sequence error lost: counted, and the image arrives intact
    "drop_segment": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "duplicate_segment": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "reorder_segments": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "corrupt_segment": UploadEffect(True, ABORT["CRC"], None, ("store", "uploads_aborted")),
    "wrong_block_crc": UploadEffect(True, ABORT["CRC"], None, ("store", "uploads_aborted")),
    # the master sends an abort and falls silent: the node drops the upload and counts the abort
    "abort_midway": UploadEffect(True, None, None, ("node", "sdo_aborts_received")),
}


def faulty_image(kind: str, image: bytes) -> bytes:
    """The image (unsigned or signed) as an image fault leaves it (wire faults: unchanged)."""
    if kind == "corrupt_image":  # one payload bit flipped after the CRC was computed
        at = image_layout.CURRENT.header_size + 36
        return image[:at] + bytes([image[at] ^ 0x10]) + image[at + 1:]
    if kind == "wrong_arch":  # another architecture id, with a CRC that matches: the arch check must refuse it
        return image_layout.patch_header(image, arch=image_layout.ARCH_SN_S + 1)
    if kind == "truncated":
        return image[:-50]
    if kind == "wrong_hmac":  # signed, but not under the key the node was provisioned with
        if image_layout.header_fields(image)["flags"] & image_layout.FLAG_HMAC:
            return image_layout.reseal(image, key=bytes(32))
        return sign_image(image, bytes(32))
    return image


class SdoFaultBus(can.BusABC):
    """A python-can bus in front of the master's: SDO requests to `node_id` pass through a fault
    at the `at`-th sub-block segment of a block download (or the end request)."""

    def __init__(self, inner: can.BusABC, node_id: int, kind: str, at: int = 40) -> None:
        if kind not in UPLOAD_WIRE_FAULTS:
            raise InputError(f"not a wire fault: {kind!r}")
        self.inner, self.kind, self.at = inner, kind, at
        self.cob = 0x600 + node_id
        self.segments = 0
        self.in_block = self.after_last = False
        self.fired = False
        self._held: can.Message | None = None
        self.channel_info = f"faults({kind}) on {getattr(inner, 'channel_info', '?')}"
        super().__init__(channel=None)

    def _recv_internal(self, timeout):
        return self.inner.recv(timeout), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.arbitration_id != self.cob:
            self.inner.send(msg, timeout)
            return
        first = msg.data[0]
        if not self.in_block:
            # only the frames of a block download are touched: other SDO traffic passes
            if (first & 0xE1) == 0xC0:  # block download initiate
                self.in_block, self.after_last = True, False
            self.inner.send(msg, timeout)
            return
        if first == 0x80 or (self.after_last and (first & 0xE3) == 0xC1):  # abort, or the end request
            self.in_block = False
            if self.kind == "abort_midway" and self.fired:
                return  # the master's link is dead
            if self.kind == "wrong_block_crc" and first != 0x80:
                data = bytearray(msg.data)
                data[1] ^= 0xFF  # CRC low byte
                msg = can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False)
                self.fired = True
            self.inner.send(msg, timeout)
            return
        self.after_last = bool(first & 0x80)
        if self.kind == "abort_midway" and self.fired:
            return
        if self.fired or self.kind == "wrong_block_crc":
            self.inner.send(msg, timeout)
            return
        self.segments += 1
        if self._held is not None:  # reorder: the held segment goes after the next one
            self.inner.send(msg, timeout)
            self.inner.send(self._held, timeout)
            self._held, self.fired = None, True
            return
        if self.segments != self.at:
            self.inner.send(msg, timeout)
            return
        if self.kind == "drop_segment":
            self.fired = True
        elif self.kind == "duplicate_segment":
            self.inner.send(msg, timeout)
            self.inner.send(msg, timeout)
            self.fired = True
        elif self.kind == "reorder_segments":
            self._held = msg
        elif self.kind == "corrupt_segment":
            data = bytearray(msg.data)
            data[3] ^= 0x01
            self.inner.send(can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False),
                            timeout)
            self.fired = True
        else:  # abort_midway: an abort instead of the segment, then silence (the master's link died)
            abort = bytearray(8)
            abort[0] = 0x80
            abort[4:8] = ABORT["GENERAL"].to_bytes(4, "little")
            self.inner.send(can.Message(arbitration_id=msg.arbitration_id, data=bytes(abort), is_extended_id=False),
                            timeout)
            self.fired = True

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()

