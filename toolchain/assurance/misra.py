"""MISRA C:2012 conformance with cppcheck's MISRA addon, checked against the recorded deviations.

The rule texts are licensed and not shipped, so findings carry rule numbers only. Each finding is
keyed by (rule, file); ``firmware_c/MISRA_DEVIATIONS.md`` records, per key, how many findings its
permit covers. Any finding beyond the recorded count, or of a rule without a permit, is unrecorded
and fails the check (``fleetlab assure misra`` exits 1 and lists them). A library file with fewer
findings than recorded is a stale record (the count must come down, so that the record never covers
a finding that is not there); the generated bundle headers' counts are the most any architecture's
bundle has (an SN-S header has fewer than a layer-table one), so they are never stale.

    fleetlab assure misra [--bundle DIR] [--table]   (--table prints the counts table)
"""
from __future__ import annotations

import re
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from .sources import ToolFailed, fw, generate_dbc, gist, include_dirs, library_sources, need, rel, run
from ..errors import InputError

_FINDING = re.compile(r"^(?P<file>[^:\n]+):(?P<line>\d+):misra-c2012-(?P<rule>[\d.]+)$", re.M)
# a counts-table row: | 15.5 | firmware_c/src/slipest_node.c | 12 | MD-15.5 |
_ROW = re.compile(r"^\|\s*(?P<rule>\d+\.\d+)\s*\|\s*(?P<file>[^|\s]+)\s*\|\s*(?P<count>\d+)\s*\|\s*(?P<permit>MD-[\d.]+)\s*\|", re.M)
_PERMIT = re.compile(r"^### (?P<permit>MD-(?P<rule>\d+\.\d+))\b", re.M)
BUNDLE_FILES = "bundle/"  # how a generated header of the checked bundle is named in the findings and the record


@dataclass
class MisraResult:
    findings: Counter = field(default_factory=Counter)  # (rule, file) -> count
    lines: dict = field(default_factory=dict)           # (rule, file) -> [line, ...]
    recorded: Counter = field(default_factory=Counter)
    permits: set = field(default_factory=set)            # rules with a permit section
    unrecorded: list = field(default_factory=list)       # (rule, file, found, recorded)
    stale: list = field(default_factory=list)            # recorded more than found (fixed since)
    other: list = field(default_factory=list)            # non-MISRA cppcheck findings
    version: str = ""

    @property
    def total(self) -> int:
        return sum(self.findings.values())

    def by_rule(self) -> Counter:
        c: Counter = Counter()
        for (rule, _), n in self.findings.items():
            c[rule] += n
        return c


def _rule_key(rule: str) -> tuple[int, int]:
    a, b = rule.split(".")
    return int(a), int(b)


def run_cppcheck(bundle: Path | None = None, work: Path | None = None,
                 sources: list[Path] | None = None) -> tuple[list[tuple[str, str, int]], list[str], str]:
    """(rule, file, line) findings of the MISRA addon over src/*.c (or `sources`), their headers and the
    DBC codec."""
    cppcheck = need("cppcheck")
    with tempfile.TemporaryDirectory() as tmp:
        gen = generate_dbc(Path(work or tmp) / "generated", bundle)
        incs = [a for d in include_dirs(bundle, gen.parent) for a in ("-I", str(d))]
        # the addon's dump files go to a build folder of this run: without one cppcheck writes them beside the
        # sources (a read-only tree in an installed wheel) and two runs at once delete each other's
        build = Path(tmp) / "cppcheck"
        build.mkdir()
        res = run([cppcheck, "--addon=misra", "--std=c99", "-q", "--enable=style", "--error-exitcode=0",
                   f"--cppcheck-build-dir={build}", "--template={file}:{line}:{id}", *incs,
                   *(sources or library_sources()), gen], timeout=1200)
        found, other = [], []
        for m in _FINDING.finditer(res.stderr):
            found.append((m["rule"], rel(m["file"], gen.parent), int(m["line"])))
        for line in res.stderr.splitlines():
            if line and "misra-c2012-" not in line and re.match(r"^[^:]+:\d+:\w+$", line):
                file, ln, ident = line.rsplit(":", 2)
                other.append(f"{rel(file, gen.parent)}:{ln}: {ident}")
        if "misra" not in res.stderr and res.returncode != 0:
            raise ToolFailed(f"cppcheck exited {res.returncode}: {gist(res.stderr, res.stdout)}", res.stderr[-3000:])
        version = run([cppcheck, "--version"]).stdout.strip()
    return found, other, version


def deviations_file() -> Path:
    return fw() / "MISRA_DEVIATIONS.md"


def read_deviations(path: Path | None = None) -> tuple[Counter, set]:
    path = path or deviations_file()
    text = path.read_text()
    recorded: Counter = Counter()
    for m in _ROW.finditer(text):
        if m["permit"] != f"MD-{m['rule']}":
            raise InputError(f"{path}: row for rule {m['rule']} names permit {m['permit']}")
        recorded[(m["rule"], m["file"])] += int(m["count"])
    permits = {m["rule"] for m in _PERMIT.finditer(text)}
    return recorded, permits


def check(bundle: Path | None = None, deviations: Path | None = None) -> MisraResult:
    found, other, version = run_cppcheck(bundle)
    return compare(found, deviations, other=other, version=version)


def compare(found: list[tuple[str, str, int]], deviations: Path | None = None, *, other: list[str] | None = None,
            version: str = "") -> MisraResult:
    """Findings (rule, file, line) against the deviation record."""
    res = MisraResult(other=other or [], version=version)
    for rule, file, line in found:
        res.findings[(rule, file)] += 1
        res.lines.setdefault((rule, file), []).append(line)
    deviations = deviations or deviations_file()
    if not deviations.exists():
        res.unrecorded = [(r, f, n, 0) for (r, f), n in res.findings.items()]
        return res
    res.recorded, res.permits = read_deviations(deviations)
    for key, n in sorted(res.findings.items(), key=lambda kv: (_rule_key(kv[0][0]), kv[0][1])):
        rule, file = key
        if n > res.recorded.get(key, 0) or rule not in res.permits:
            res.unrecorded.append((rule, file, n, res.recorded.get(key, 0)))
    for key, n in res.recorded.items():
        if res.findings.get(key, 0) < n and not key[1].startswith(BUNDLE_FILES):
            res.stale.append((key[0], key[1], res.findings.get(key, 0), n))
    return res


def counts_table(res: MisraResult) -> str:
    """The record's counts table from these findings; a bundle header's row keeps a higher recorded count
    (another architecture's bundle has more, see the module's docstring)."""
    rows = ["| Rule | File | Findings | Permit |", "|---|---|---:|---|"]
    for (rule, file), n in sorted(res.findings.items(), key=lambda kv: (_rule_key(kv[0][0]), kv[0][1])):
        if file.startswith(BUNDLE_FILES):
            n = max(n, res.recorded.get((rule, file), 0))
        rows.append(f"| {rule} | {file} | {n} | MD-{rule} |")
    return "\n".join(rows)
