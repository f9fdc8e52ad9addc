"""Real-time pacing of a sent stream: each frame waits until its due time (seconds after the start) on a
clock. The host tools pace on the wall clock; a test gives a SimulatedClock, whose time moves only when the
pacer sleeps, so what it checks is the schedule the stream kept (how often it waited, where its clock
ended), not how fast a loaded machine ran."""

from __future__ import annotations

import time
from dataclasses import dataclass


class WallClock:
    """time.perf_counter and time.sleep."""

    now = staticmethod(time.perf_counter)
    sleep = staticmethod(time.sleep)


class SimulatedClock:
    """A clock that stands still until slept on: sleep(d) moves it on by d."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += seconds


@dataclass
class Pacer:
    """wait(due) returns once `due` seconds have passed on `clock` since the pacer was made."""

    clock: WallClock | SimulatedClock
    start: float = 0.0
    waits: int = 0  # waits that slept (their due time was not reached yet)

    # a due time less than this ahead counts as reached: below any clock's resolution, and it keeps a simulated
    # clock's float sums (c * period against period added c times) from making nanosecond waits
    RESOLUTION_S = 1e-9

    def __post_init__(self) -> None:
        self.start = self.clock.now()

    def wait(self, due: float) -> None:
        delay = self.start + due - self.clock.now()
        if delay > self.RESOLUTION_S:
            self.clock.sleep(delay)
            self.waits += 1

    def elapsed(self) -> float:
        return self.clock.now() - self.start
