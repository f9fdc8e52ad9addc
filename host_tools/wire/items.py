"""The unit every link writes: a frame, or a corrupted rendering of one (fault injection)."""

from __future__ import annotations

from dataclasses import dataclass

from .dbc import Frame


@dataclass(frozen=True, slots=True)
class WireItem:
    """One unit written to the link: a frame, or a corrupted rendering of one.

    corrupt: None (send `frame` as is), 'bad_crc' (serial: CRC inverted; slcan: malformed
    line) or 'length_mismatch' (serial: dlc byte disagrees with the packet length).
    fault: index into the injection log of the fault that produced this item, or -1.
    """

    frame: Frame
    corrupt: str | None = None
    fault: int = -1
