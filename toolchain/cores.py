"""How many CPU cores this process may run on.

The one place that asks: the affinity mask where the platform has one (a container, `taskset` or a
batch scheduler may grant fewer cores than the machine has), else the machine's count. AcoMerge's
thread choice, `bench fusion` and the assurance checks all size their work by it.
"""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may use (at least 1)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1
