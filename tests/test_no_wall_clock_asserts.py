"""Issue 31: no test compares a wall-clock reading with a constant, except a wait's marked safety net
(tests/wall_clock.py has the rule). A loaded machine must not fail a test that found no bug."""

from __future__ import annotations

from pathlib import Path

from wall_clock import findings, scan

TESTS = Path(__file__).resolve().parent


def test_no_test_compares_the_wall_clock_outside_a_safety_net():
    assert scan(TESTS) == []


def test_the_rule_finds_planted_wall_clock_assertions():
    """Negative controls: each planted comparison is found; the marked safety net and the simulated clock
    are not."""
    planted = '''
import time
from time import perf_counter

def test_paced(stats):
    assert stats.wall_s >= 1.93          # a figure read from a result, no clock call here: not this rule
    t0 = time.perf_counter()
    run()
    elapsed = time.perf_counter() - t0
    assert elapsed < 0.9                 # through a name
    assert perf_counter() - t0 > 1.0     # the bare import
    self.start = time.monotonic_ns()
    assert time.time() > 0 and self.start < 10**12

def wait(done):
    deadline = time.monotonic() + 5
    while not done() and time.monotonic() < deadline:  # safety net
        pass

def test_ticks(clock, pacer):
    assert pacer.waits == 99 and clock.now() == 1.98
'''
    got = sorted(f.split(": ", 1)[1] for f in findings(planted))
    assert got == sorted(["elapsed < 0.9", "perf_counter() - t0 > 1.0", "time.time() > 0", "self.start < 10 ** 12"])


def test_an_unmarked_wait_is_a_finding():
    """The same wait without its marker is found: the marker, not the loop shape, is what the rule accepts."""
    wait = "import time\ndeadline = time.monotonic() + 5\nwhile time.monotonic() < deadline:\n    pass\n"
    assert findings(wait, "w.py") == ["w.py:3: time.monotonic() < deadline"]
