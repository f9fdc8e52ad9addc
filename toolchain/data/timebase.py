"""One time base for streams logged at different rates (the import's interpolation rule).

Every stream is a list of (header stamp in ns, values). The rule, as stated in
docs/your_rover.md:
1. A message whose stamp is not after the previous kept stamp of its stream is
   dropped (counted `backwards_stamps`); one holding NaN/Inf is dropped
   (`nonfinite`); one beyond the sensor's range is dropped (`saturated_messages`).
2. A pause longer than `max_gap_s` between two kept messages of any stream is a gap
   (`gaps`, counted per stream): nothing is interpolated across it and the log is cut there
   (`gap_s`: the time between the segments left).
3. Segments are the times every stream covers; within one, grid times are
   start + k / rate (no extrapolation past the segment's end) and each stream's
   values at a grid time are the linear interpolation between its two kept
   messages around it (a message exactly on a grid time gives its own value).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

NS = 1_000_000_000


@dataclass
class Stream:
    """One section of a log: header stamps (ns) and values (n, k) in physical units."""

    section: str
    t_ns: np.ndarray  # (n,) int64
    values: np.ndarray  # (n, k) float64
    group: str | None = None  # streams of one group come from the same messages (rows of one CSV file)

    def __len__(self) -> int:
        return len(self.t_ns)


def clean(stream: Stream, drops: Counter, limit: float | None = None) -> Stream:
    """Drop (and count) NaN/Inf, out-of-range and not-increasing-stamp messages."""
    t, v = np.asarray(stream.t_ns, dtype=np.int64), np.asarray(stream.values, dtype=np.float64)
    finite = np.isfinite(v).all(axis=1)
    drops["nonfinite"] += int(np.count_nonzero(~finite))
    keep = finite
    if limit is not None:
        in_range = (np.abs(v) < limit).all(axis=1) | ~finite
        drops["saturated_messages"] += int(np.count_nonzero(~in_range))
        keep = keep & in_range
    t, v = t[keep], v[keep]
    if len(t):
        prev = np.concatenate([[np.iinfo(np.int64).min], np.maximum.accumulate(t)[:-1]])
        forward = t > prev
        drops["backwards_stamps"] += int(np.count_nonzero(~forward))
        t, v = t[forward], v[forward]
    return Stream(stream.section, t, v)


def coverage(t_ns: np.ndarray, max_gap_ns: int, drops: Counter) -> list[tuple[int, int]]:
    """Intervals [first, last] stamp of the stream's runs without a gap; gaps counted."""
    if len(t_ns) == 0:
        return []
    cut = np.flatnonzero(np.diff(t_ns) > max_gap_ns)
    drops["gaps"] += len(cut)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(t_ns) - 1]])
    return [(int(t_ns[a]), int(t_ns[b])) for a, b in zip(starts, ends)]


def intersect(a: list[tuple[int, int]], b: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out, i, j = [], 0, 0
    while i < len(a) and j < len(b):
        lo, hi = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if lo < hi:
            out.append((lo, hi))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


def segments(streams: list[Stream], max_gap_s: float, drops: Counter,
             end_margin_ns: dict[str, int] | None = None) -> list[tuple[int, int]]:
    """Time spans (ns) that every stream covers without a gap.

    `end_margin_ns` shortens a stream's runs at their end (the ground truth must reach one
    grid step past the last sample, whose distance step ends there).
    """
    gap_ns = int(round(max_gap_s * NS))
    margin = end_margin_ns or {}
    spans = None
    for s in streams:
        runs = [(a, b - margin.get(s.section, 0)) for a, b in coverage(s.t_ns, gap_ns, drops)]
        spans = runs if spans is None else intersect(spans, runs)
    spans = spans or []
    drops["gap_s"] += sum(b[0] - a[1] for a, b in zip(spans, spans[1:])) / NS  # time between segments
    return spans


def grid(start_ns: int, end_ns: int, rate_hz: float, extra: int = 0) -> np.ndarray:
    """start + k / rate (rounded to the ns) for every k that stays within [start, end], plus `extra` points after."""
    n = int(np.floor((end_ns - start_ns) * rate_hz / NS + 1e-9)) + 1 + extra
    return start_ns + np.round(np.arange(n) * (NS / rate_hz)).astype(np.int64)


def resample(stream: Stream, t_grid: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column at the grid times (all inside the stream's span)."""
    origin = t_grid[0]
    x = (t_grid - origin).astype(np.float64)
    xp = (stream.t_ns - origin).astype(np.float64)
    return np.column_stack([np.interp(x, xp, stream.values[:, k]) for k in range(stream.values.shape[1])])


def messages_per_window(t_ns: np.ndarray, starts_ns: np.ndarray, length_ns: int) -> np.ndarray:
    """Number of messages with stamp in [start, start + length) for each window start."""
    return np.searchsorted(t_ns, starts_ns + length_ns, side="left") - np.searchsorted(t_ns, starts_ns, side="left")
