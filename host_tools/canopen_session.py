"""A python `canopen` master connected to a slipest CANopen node, whichever way the node runs:

- `inproc`: the C library in this process on a python-can `virtual` bus (CanopenBridge), its
  model slots on a RamNvm;
- `slcan` / `cobs`: the emulator process (`slipest_emu --profile canopen`) on a pseudo-terminal,
  its slots in an NVM file; over `cobs` the CAN frames travel in the serial link's COBS packets
  (`CobsCanBus`), so python `canopen` runs unchanged on either;
- `bus`: any python-can bus given by the caller (a real adapter to a rover's node).

`stream_telemetry` sends telemetry RPDOs with flow control (the node must keep up: on a real
bus the estimator runs at the sensor rate).
"""

from __future__ import annotations

import itertools
import os
import subprocess
import threading
import time
from pathlib import Path
from typing import Callable

import can
import numpy as np

from .canopen_master import EstimateCollector, SlipestMaster, telemetry_rpdos
from .canopen_node import CanopenBridge, CCanopenNode, RamNvm, nvm_sectors
from .links import open_can_bus
from .wire.dbc import Frame
from .wire.serial_framing import PacketDecoder, Rejected, encode_packet
from fleetlab.errors import InputError

_channels = itertools.count()


def eds_for(build_dir: Path) -> Path:
    """The EDS the C build generated beside the node's tables (one source: canopen_od/objects.py)."""
    p = Path(build_dir) / "generated" / "slipest.eds"
    if not p.is_file():
        raise OSError(f"{build_dir}: no generated/slipest.eds (configure and build the C library first)")
    return p


class CobsCanBus(can.BusABC):
    """A python-can bus over the serial link's COBS + CRC-16 packets (pyserial port or pty): the
    same CAN frames as on the CAN bus, one frame per packet."""

    def __init__(self, channel: str, baudrate: int = 921600, **kwargs) -> None:
        import serial

        self.port = serial.Serial(channel, baudrate=baudrate, timeout=0.01)
        self.decoder = PacketDecoder()
        self._pending: list[can.Message] = []
        self.rejected = 0
        self.channel_info = f"cobs:{channel}"
        self._wlock = threading.Lock()
        super().__init__(channel=channel, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        data = encode_packet(Frame(msg.arbitration_id, bytes(msg.data)))
        with self._wlock:
            self.port.write(data)

    def _recv_internal(self, timeout: float | None):
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._pending:
            data = self.port.read(max(1, self.port.in_waiting))
            for r in self.decoder.feed(data) if data else ():
                if isinstance(r, Rejected):
                    self.rejected += 1
                else:
                    self._pending.append(can.Message(arbitration_id=r.can_id, data=r.data, is_extended_id=False,
                                                     timestamp=time.time()))
            if deadline is not None and time.monotonic() >= deadline:
                break
        if self._pending:
            return self._pending.pop(0), False
        return None, False

    def shutdown(self) -> None:
        super().shutdown()
        self.port.close()


class CanopenSession:
    """Master + node. `link`: inproc, slcan, cobs (emulator started here) or bus (caller's bus)."""

    def __init__(self, link: str, eds: Path, node_id: int = 5, lib: Path | None = None, emulator: Path | None = None,
                 nvm_file: Path | None = None, builtin_image: Path | None = None, bus: can.BusABC | None = None,
                 nvm: RamNvm | None = None, wrap_bus: Callable[[can.BusABC], can.BusABC] | None = None,
                 builtin_model: bool = True, emulator_args: tuple[str, ...] = ()) -> None:
        """`builtin_model` (inproc): False boots the node without a built-in model, as a flight image;
        `emulator_args` (slcan, cobs): more options for slipest_emu (e.g. its NVM cut hook)."""
        self.link, self.node_id = link, node_id
        self.bridge: CanopenBridge | None = None
        self.proc: subprocess.Popen | None = None
        if link == "inproc":
            if lib is None:
                raise InputError("the inproc link needs the host library (libslipest_host.so)")
            channel = f"fleetlab-canopen-{os.getpid()}-{next(_channels)}"
            self.nvm = nvm if nvm is not None else RamNvm(nvm_sectors(lib))
            self.node = CCanopenNode(lib, node_id, nvm=self.nvm, builtin=builtin_model)
            self.bridge = CanopenBridge(self.node, can.Bus(interface="virtual", channel=channel))
            master_bus = can.Bus(interface="virtual", channel=channel)
        elif link in ("slcan", "cobs"):
            if emulator is None:
                raise InputError(f"the {link} link needs the emulator (slipest_emu)")
            args = [str(emulator), "--pty", "--link", link, "--profile", "canopen", "--node-id", str(node_id)]
            if nvm_file is not None:
                args += ["--nvm", str(nvm_file)]
            if builtin_image is not None:
                args += ["--model", str(builtin_image)]
            args += list(emulator_args)
            self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
            line = self.proc.stdout.readline().decode() if self.proc.stdout else ""
            if not line.startswith("PTY "):
                err = self.proc.stderr.read().decode()[-500:] if self.proc.stderr else ""
                self.proc.kill()
                raise OSError(f"{emulator.name} did not start: {line!r} {err}")
            threading.Thread(target=self._drain, daemon=True).start()
            pty = line.split()[1]
            master_bus = open_can_bus("slcan", pty, bitrate=500000) if link == "slcan" else CobsCanBus(pty)
        elif link == "bus":
            if bus is None:
                raise InputError("link 'bus' needs a python-can bus")
            master_bus = bus
        else:
            raise InputError(f"unknown CANopen link {link!r} (inproc, slcan, cobs or bus)")
        if wrap_bus is not None:  # e.g. fault injection between master and node
            master_bus = wrap_bus(master_bus)
        self.master = SlipestMaster(master_bus, eds, node_id)
        self.node_remote = self.master.node

    def _drain(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        self.stderr_tail: list[str] = []
        for line in iter(self.proc.stderr.readline, b""):
            self.stderr_tail = (self.stderr_tail + [line.decode(errors="replace").rstrip()])[-20:]

    def _expect_bootup(self, action: Callable[[], None], timeout: float) -> None:
        """Run `action` and wait for the node's boot-up message. The listener is in place before the
        action (canopen's wait_for_bootup starts listening only when called, so a fast node's boot-up
        could come before it)."""
        booted = threading.Event()
        cob = 0x700 + self.node_id

        def on_heartbeat(_cob: int, data: bytearray, _ts: float) -> None:
            if data and data[0] == 0x00:
                booted.set()

        net = self.master.network
        net.subscribe(cob, on_heartbeat)
        try:
            action()
            if not booted.wait(timeout):
                raise OSError(f"node {self.node_id}: no boot-up message within {timeout} s")
        finally:
            net.unsubscribe(cob, on_heartbeat)

    def reset_node(self, timeout: float = 3.0) -> None:
        """NMT reset node; returns after the boot-up message."""
        self._expect_bootup(lambda: self.master.node.nmt.send_command(0x81), timeout)

    def power_cycle(self, timeout: float = 3.0) -> None:
        """In-process only: the node restarts from its NVM as after a power loss; returns after its
        boot-up message."""
        if self.bridge is None:
            raise InputError("power_cycle needs the inproc link (kill and restart the emulator otherwise)")
        self._expect_bootup(self.bridge.power_cycle, timeout)

    def frames_in(self) -> int | None:
        return self.bridge.frames_in if self.bridge is not None else None

    def close(self) -> None:
        try:
            self.master.close()
        except (can.CanError, OSError):
            # closing the adapter writes to the pty: gone when the emulator process died (a power-cut test)
            if self.proc is None or self.proc.poll() is None:
                raise
        finally:
            if self.bridge is not None:
                self.bridge.close()
            if self.proc is not None:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=3)
                except subprocess.TimeoutExpired:
                    self.proc.kill()

    def __enter__(self) -> "CanopenSession":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def stream_telemetry(session: CanopenSession, samples_q: np.ndarray, collector: EstimateCollector,
                     first_counter: int = 0, windows_ahead: int = 2, stop: threading.Event | None = None,
                     send: Callable[[Frame], None] | None = None) -> int:
    """Send the RPDOs of `samples_q` window by window, never more than `windows_ahead` windows
    ahead of the estimates received (flow control that works on every link). Returns the number
    of windows sent."""
    frames = telemetry_rpdos(samples_q, session.node_id, first_counter)
    per_window = 3 * 100
    base = collector.count()
    send = send or (lambda f: session.master.network.send_message(f.can_id, f.data))
    n_windows = len(frames) // per_window
    for w in range(n_windows):
        if stop is not None and stop.is_set():
            return w
        deadline = time.monotonic() + 10.0
        while collector.count() - base < w - windows_ahead and time.monotonic() < deadline:
            time.sleep(0.0005)
        for f in frames[w * per_window:(w + 1) * per_window]:
            send(f)
    return n_windows
