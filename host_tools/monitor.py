"""`fleetlab monitor can`: watch slip estimates and status frames on a CAN bus (or replay a log).

Every frame is decoded with the DBC (cantools); estimates are shown once their three
frames arrived, status frames as one line. Frames the DBC does not know, or with the
wrong length, are counted and shown — never skipped silently.

The node's STATUS counters count over its whole life, and the monitor may start long after it: the first status
report seen is the baseline (shown as the node's totals), every later one also shows its counters as the
difference from that baseline (across a wrap), i.e. what happened while the monitor watched.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import can

from .links import from_message
from .sources import log_messages
from .stream import status_delta
from .wire.dbc import Frame, OutputAssembler, StatusReport, WindowEstimate, by_id
from .wire.serial_framing import Rejected


@dataclass
class MonitorStats:
    frames: int = 0
    estimates: list[WindowEstimate] = field(default_factory=list)
    statuses: list[StatusReport] = field(default_factory=list)
    unknown: int = 0  # frames not in the DBC or not decodable
    problems: list[str] = field(default_factory=list)

    def counters(self) -> StatusReport | None:
        """The last status report with its counters counted from the first one seen (the baseline): what the node
        did while it was watched. None before two reports."""
        if len(self.statuses) < 2:
            return None
        return status_delta(self.statuses[-1], self.statuses[0])


class Monitor:
    """Decodes a stream of frames; `feed` returns a printable line or None."""

    def __init__(self, show_all: bool = False) -> None:
        self.asm = OutputAssembler()
        self.stats = MonitorStats()
        self.show_all = show_all

    def feed(self, frame: Frame | Rejected, t: float = 0.0) -> str | None:
        self.stats.frames += 1
        if isinstance(frame, Rejected):
            self.stats.unknown += 1
            return f"? undecodable frame ({frame.reason})"
        codec = by_id().get(frame.can_id)
        if codec is None or len(frame.data) != codec.length:
            self.stats.unknown += 1
            why = "not in the DBC" if codec is None else f"{len(frame.data)} bytes, DBC says {codec.length}"
            return f"? 0x{frame.can_id:03X} [{frame.data.hex()}] {why}"
        n_err = len(self.asm.errors)
        out = self.asm.feed(frame, t) if codec.name.startswith(("SLIP_", "STATUS_")) else None
        if len(self.asm.errors) > n_err:
            self.stats.problems.extend(self.asm.errors[n_err:])
            return "! " + self.asm.errors[-1]
        if isinstance(out, WindowEstimate):
            self.stats.estimates.append(out)
            cls = "invalid" if out.slip_class == 255 else str(out.slip_class)
            return (f"estimate window {out.window_counter}: class {cls} (f32 {out.slip_class_f32}) flags "
                    f"{out.flags:#04x} n {out.n_samples} sat {out.saturations} logits {out.logits}")
        if isinstance(out, StatusReport):
            return self.status_line(out)
        if self.show_all:
            return f"{codec.name} {codec.decode_dict(frame.data)}"
        return None

    def status_line(self, st: StatusReport) -> str:
        """Record a status report; its line: the node's totals, and from the second report on the counters since
        the first one (the monitor's start)."""
        self.stats.statuses.append(st)
        line = (f"status: model {st.model_hash:08x} v{st.lib_version >> 8}.{st.lib_version & 0xFF} "
                f"windows {st.windows_done} rx {st.frames_received} rejected {st.frames_rejected} "
                f"dropped {st.samples_dropped} flagged {st.windows_flagged}")
        d = self.stats.counters()
        if d is not None:
            line += (f"; since the monitor started: windows {d.windows_done} rx {d.frames_received} rejected "
                     f"{d.frames_rejected} dropped {d.samples_dropped} flagged {d.windows_flagged}")
        return line


def monitor_bus(bus: can.BusABC, duration: float = 0.0, count: int = 0, show: Callable[[str], None] | None = print,
                logger: can.Listener | None = None, show_all: bool = False) -> MonitorStats:
    mon = Monitor(show_all)
    end = time.monotonic() + duration if duration > 0 else None
    while end is None or time.monotonic() < end:
        msg = bus.recv(timeout=0.1)
        if msg is None:
            continue
        if logger is not None:
            logger(msg)
        line = mon.feed(from_message(msg), msg.timestamp)
        if line and show:
            show(line)
        if count and len(mon.stats.estimates) >= count:
            break
    return mon.stats


def monitor_log(path: Path, show: Callable[[str], None] | None = print, show_all: bool = False) -> MonitorStats:
    mon = Monitor(show_all)
    for msg in log_messages(path):
        if msg.is_error_frame:
            continue
        line = mon.feed(from_message(msg), msg.timestamp)
        if line and show:
            show(line)
    return mon.stats
