"""Where fleetlab's work runs: the cores this process may use, how busy they are, how many torch threads a
piece of work takes, and the torch device a `--device` name means.

The one place that asks. AcoMerge's thread choice, the MCCV jobs, `bench fusion`, the assurance checks,
`fuse` and `evaluate` all size their work here. torch is imported inside the functions that need it: the
assurance checks and `fleetlab --help` only ask for cores and should not pay for loading torch.
"""

from __future__ import annotations

import contextlib
import os
import time
from typing import TYPE_CHECKING

from .errors import InputError

if TYPE_CHECKING:
    import torch

MAX_THREADS = 4  # beyond this a generation's small GEMMs (and a small net's training) gain nothing from more threads
AUTO_THREADS = 0  # `threads` value meaning: chosen when the work starts, from the cores free then
DEVICES = ("cpu", "cuda", "auto")


def usable_cores() -> int:
    """The cores this process may use (at least 1): the affinity mask where the platform has one (a container,
    `taskset` or a batch scheduler may grant fewer cores than the machine has), else the machine's count."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def _cpu_times() -> tuple[float, float] | None:
    """(idle, total) jiffies of all CPUs from /proc/stat, or None where there is none."""
    try:
        with open("/proc/stat") as f:
            fields = [float(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return fields[3] + (fields[4] if len(fields) > 4 else 0.0), sum(fields[:8])


def busy_cores(window_s: float = 0.05) -> float:
    """How many CPUs other processes kept busy over the last `window_s` (this one sleeps meanwhile)."""
    before = _cpu_times()
    time.sleep(window_s)
    after = _cpu_times()
    if before is None or after is None or after[1] <= before[1]:
        return 0.0
    busy_fraction = 1.0 - (after[0] - before[0]) / (after[1] - before[1])
    return busy_fraction * (os.cpu_count() or 1)


def default_threads() -> int:
    """Threads for one piece of work (an AcoMerge run, a fuse): the cores this process may use that no other
    process keeps busy right now, at most MAX_THREADS, at least 1.

    Why: a generation's intra-op threads meet at a barrier several times per generation. With a
    core taken by another process, one of two threads waits for its time slice at every barrier,
    and a 2-thread SN-S run took 11.3 s instead of 1.1 s on one thread (2 cores, load 6,
    `fleetlab bench fusion --load`). So a run takes only the cores that are free when it starts.
    """
    cores = usable_cores()
    free = min(cores, (os.cpu_count() or 1) - busy_cores())
    return max(1, min(MAX_THREADS, cores, int(free + 0.25)))


def run_threads(threads: int) -> int:
    """`threads` as given, or chosen now (`default_threads`) for AUTO_THREADS."""
    return default_threads() if threads == AUTO_THREADS else threads


@contextlib.contextmanager
def torch_threads(threads: int):
    """torch's intra-op threads set to `threads` (AUTO_THREADS: chosen now) for the block, and put back after.
    One thread is what a small net's training and every MCCV job use: identical float results whatever the
    worker count, and no barrier waits on a busy machine."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(run_threads(threads))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def resolve_device(name: str) -> torch.device:
    """'cpu', 'cuda' (or 'cuda:N') or 'auto' -> a torch.device; one line (InputError) where there is no GPU."""
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            build = "a CPU-only torch build" if torch.version.cuda is None else f"torch built for CUDA {torch.version.cuda}"
            raise InputError(f"--device {name}: no CUDA GPU is available here ({build}); use --device cpu or auto")
        dev = torch.device(name)
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(f"--device {name}: this machine has {torch.cuda.device_count()} CUDA device(s)")
        return dev
    raise InputError(f"unknown device {name!r}; choose one of {', '.join(DEVICES)}")


def device_label(device: torch.device | str) -> str:
    """A human name for progress bars and reports, e.g. 'cuda:0 (NVIDIA H100 80GB HBM3)'."""
    import torch

    device = torch.device(device)
    if device.type == "cuda":
        index = device.index if device.index is not None else torch.cuda.current_device()
        return f"cuda:{index} ({torch.cuda.get_device_name(index)})"
    return "cpu"
