"""Time-series CSV logs: one CSV per sensor (and per drive), read into one set of streams per drive.

Each profile section names a `file` glob pattern, its time column and unit, and its columns. Sections
with the same pattern and time column (an IMU file that also carries the attitude, say) are one *file
group*: each of its files is read once, and a row is one message of every section it feeds, so a bad
row is counted once, not once per section.

A row is dropped and counted `non_numeric` when a cell the profile uses holds text (or nothing, or the
row is short); a number written as nan/inf is kept here for the import's cleaning, which counts it
`nonfinite` (`timebase.clean`).

**One drive per file.** A pattern may match several files. They are paired into drives:
1. by their common suffix (the text the pattern's wildcards match): when every file group matches
   more than one file and they share suffixes, each suffix they all have is one drive (`imu_01.csv`
   with `pro_01.csv`, whatever their times), and the files whose suffix another group lacks are
   paired by time among themselves (2.);
2. otherwise by time: files of different groups whose time spans overlap are one drive (transitively),
   and the files of one group in one drive are joined in time order as consecutive parts of one log,
   which they may be only if their spans do not overlap (else one error line names the two files).
   A drive without a file of every group is left out, counted (`unpaired_files`) and named in a note.
Files whose time spans overlap are never joined into one stream.
"""

from __future__ import annotations

import csv
import glob
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .log_sources import wheel_channels
from .rover_profile import TIME_UNITS, ProfileError, RoverProfile, StreamSpec
from .timebase import Stream
from ..errors import InputError


@dataclass
class Drive:
    """The streams of one drive and what reading its files dropped."""

    name: str | None  # the files' common suffix, `driveNN`, or None for the folder's only drive
    streams: dict[str, Stream]
    drops: Counter
    files: list[str]  # the files read, relative to the folder


@dataclass
class _Group:
    """Sections read from the same files: (section, column keys) in read order."""

    pattern: str
    time_column: str
    time_unit: str
    sections: list[tuple[str, StreamSpec]]

    def wanted(self) -> list[tuple[str, str]]:
        """(profile key, column) of the time column, then of every section's columns."""
        out = [(f"{self.sections[0][0]}.time_column", self.time_column)]
        for section, spec in self.sections:
            out += [(f"{section}.{key}", col) for key, cols in spec.columns.items() for col in cols]
        return out


@dataclass
class _File:
    path: Path
    rel: str
    group: int
    t: np.ndarray  # (n,) ns
    values: np.ndarray  # (n, k)
    drops: Counter

    @property
    def span(self) -> tuple[int, int]:
        return (int(self.t.min()), int(self.t.max())) if len(self.t) else (0, -1)


def _groups(profile: RoverProfile) -> list[_Group]:
    groups: dict[tuple, _Group] = {}
    for section, spec in profile.streams.items():
        key = (spec.csv.file, spec.csv.time_column, spec.csv.time_unit)
        groups.setdefault(key, _Group(*key, [])).sections.append((section, spec))
    return list(groups.values())


def _read_file(path: Path, rel: str, gi: int, group: _Group, profile: RoverProfile) -> _File:
    drops: Counter = Counter()
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        index = []
        for key, col in group.wanted():
            if col not in header:
                raise ProfileError(profile.path, key, f"column {col!r} is not in {path.name} "
                                   f"(its columns: {', '.join(header) or 'none'})")
            index.append(header.index(col))
        rows = []
        for fields in reader:
            if not fields or all(not f.strip() for f in fields):
                continue
            try:
                rows.append([float(fields[i]) for i in index])
            except (ValueError, IndexError):
                drops["non_numeric"] += 1
    a = np.array(rows, dtype=np.float64).reshape(-1, len(index))
    bad_time = ~np.isfinite(a[:, 0])
    drops["nonfinite"] += int(np.count_nonzero(bad_time))
    a = a[~bad_time]
    t = np.round(a[:, 0] * TIME_UNITS[group.time_unit]).astype(np.int64)
    return _File(path, rel, gi, t, a[:, 1:], drops)


_WILDCARD = re.compile(r"\*|\?|\[[^\]]*\]")


def suffix_of(pattern: str, rel: str) -> tuple[str, ...] | None:
    """The text the pattern's wildcards match in a relative path (None if it does not match)."""
    parts, pos = [], 0
    for m in _WILDCARD.finditer(pattern):
        parts.append(re.escape(pattern[pos:m.start()]))
        w = m.group()
        parts.append("([^/]*)" if w == "*" else "([^/])" if w == "?" else "([" + w[1:-1].replace("!", "^", 1) + "])")
        pos = m.end()
    parts.append(re.escape(pattern[pos:]))
    match = re.fullmatch("".join(parts), rel)
    return match.groups() if match else None


def _overlap(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _pair_by_suffix(files: list[list[_File]], groups: list[_Group], drops: Counter,
                    notes: list[str]) -> list[tuple[str, list[_File]]] | None:
    """Drives by common suffix, when every group matches several files and they share suffixes; the
    files left over are paired by time among themselves (`driveNN`)."""
    if any(len(fs) < 2 for fs in files):
        return None
    keys = [{suffix_of(g.pattern, f.rel): f for f in fs} for g, fs in zip(groups, files)]
    if any(None in k or len(k) != len(fs) for k, fs in zip(keys, files)):
        return None
    common = set(keys[0]).intersection(*keys[1:])
    if not common:
        return None
    out = [("_".join(s for s in key if s) or "drive", [k[key] for k in keys]) for key in sorted(common)]
    rest = [[f for key, f in k.items() if key not in common] for k in keys]
    if any(rest):
        rest_drives = _pair_by_time(rest, drops, notes)
        out += [(f"drive{i + 1:02d}", fs) for i, (_, fs) in enumerate(rest_drives)]
    return out


def _pair_by_time(files: list[list[_File]], drops: Counter, notes: list[str]) -> list[tuple[str | None, list[_File]]]:
    flat = [f for fs in files for f in fs if len(f.t)]
    parent = list(range(len(flat)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, a in enumerate(flat):
        for j in range(i + 1, len(flat)):
            if a.group != flat[j].group and _overlap(a.span, flat[j].span):
                parent[find(i)] = find(j)
    comps: dict[int, list[_File]] = {}
    for i, f in enumerate(flat):
        comps.setdefault(find(i), []).append(f)
    drives = sorted(comps.values(), key=lambda fs: min(f.span[0] for f in fs))
    out = []
    for fs in drives:
        present = {f.group for f in fs}
        if len(present) < len(files):
            drops["unpaired_files"] += len(fs)
            notes.append(f"{', '.join(f.rel for f in fs)}: no file of every sensor with the same suffix or "
                         "overlapping in time; left out")
            continue
        for g in present:
            same = sorted((f for f in fs if f.group == g), key=lambda f: f.span)
            for a, b in zip(same, same[1:]):
                if _overlap(a.span, b.span):
                    raise InputError(f"{a.path.parent}: {a.rel} and {b.rel} overlap in time, so they are not parts of "
                                     "one log, and nothing pairs them with the other sensors' files: name the files of "
                                     "one drive with a common suffix (imu_01.csv with wheels_01.csv)")
        out.append(fs)
    if len(out) == 1:
        return [(None, out[0])]
    return [(f"drive{k + 1:02d}", fs) for k, fs in enumerate(out)]


def _streams(profile: RoverProfile, groups: list[_Group], files: list[_File]) -> dict[str, Stream]:
    streams = {}
    for gi, group in enumerate(groups):
        parts = sorted((f for f in files if f.group == gi), key=lambda f: f.span)
        t = np.concatenate([f.t for f in parts])
        values = np.concatenate([f.values for f in parts])
        col = 0
        for section, spec in group.sections:
            width = sum(len(cols) for cols in spec.columns.values())
            v = values[:, col:col + width]
            col += width
            if section == "wheels":
                v = wheel_channels(v, profile)
            elif section == "attitude":
                v = v * profile.angle_scale
            streams[section] = Stream(section, t, v, group=f"{group.pattern}|{group.time_column}"
                                      if len(group.sections) > 1 else None)
    return streams


def read_csv_drives(source: Path, profile: RoverProfile, progress: bool = True,
                    notes: list[str] | None = None) -> list[Drive]:
    """The drives of a folder of time-series CSVs (see the module docstring), each with its streams."""
    notes = notes if notes is not None else []
    groups = _groups(profile)
    files: list[list[_File]] = []
    for gi, group in enumerate(groups):
        paths = sorted(Path(p) for p in glob.glob(str(source / group.pattern)))
        if not paths:
            section = group.sections[0][0]
            raise ProfileError(profile.path, f"{section}.file", f"no file matches {group.pattern!r} in {source} "
                               f"(it has: {', '.join(sorted(p.name for p in source.glob('*.csv'))) or 'no CSV files'})")
        files.append([_read_file(p, p.relative_to(source).as_posix(), gi, group, profile)
                      for p in tqdm(paths, desc=f"reading {source.name} {group.pattern}", unit="file",
                                    disable=not progress)])
    drops: Counter = Counter()
    paired = _pair_by_suffix(files, groups, drops, notes) if len(files) > 1 else None
    if paired is None:
        paired = _pair_by_time(files, drops, notes)
    if not paired:
        raise InputError(f"{source}: no drive has a file of every sensor overlapping in time ({'; '.join(notes)})")
    drives = []
    for k, (name, fs) in enumerate(paired):
        d: Counter = Counter(drops) if k == 0 else Counter()  # files left out: counted with the first drive
        for f in fs:
            d.update(f.drops)
        drives.append(Drive(name, _streams(profile, groups, fs), d, sorted(f.rel for f in fs)))
    return drives
