"""Statement and branch coverage of the C library by its own C tests (ctest), with gcov.

A host build with ``--coverage -O0`` runs ctest; gcovr then summarises the library sources
(firmware_c/src/*.c and the generated codec), not the tests. Lines that stay uncovered are
listed so the report can say why.

    fleetlab assure coverage [--bundle DIR] [--build DIR]
"""
from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from ..paths import default_bundle, repo_root
from .sources import need, rel, run

GOAL_LINES = 95.0
GOAL_BRANCHES = 90.0


@dataclass
class FileCoverage:
    name: str
    lines: int
    lines_hit: int
    branches: int
    branches_hit: int
    missed_lines: list[int] = field(default_factory=list)


@dataclass
class CoverageResult:
    files: list[FileCoverage]
    ctest_summary: str
    gcovr_version: str

    def _pct(self, hit: str, total: str) -> float:
        t = sum(getattr(f, total) for f in self.files)
        return 100.0 * sum(getattr(f, hit) for f in self.files) / t if t else 0.0

    @property
    def line_pct(self) -> float:
        return self._pct("lines_hit", "lines")

    @property
    def branch_pct(self) -> float:
        return self._pct("branches_hit", "branches")

    def handwritten(self) -> "CoverageResult":
        """The same figures without the cantools-generated codec (its range checks and the
        pack/unpack pairs of frames the node only sends or only receives are never called)."""
        return CoverageResult([f for f in self.files if not f.name.startswith("generated/")],
                              self.ctest_summary, self.gcovr_version)


def measure(build: Path, bundle: Path | None = None) -> CoverageResult:
    tree = repo_root()
    need("gcov")
    build = Path(build)
    run(["cmake", "-S", tree, "-B", build, f"-DSLIPEST_BUNDLE={Path(bundle or default_bundle()).resolve()}",
         f"-DPython3_EXECUTABLE={sys.executable}", "-DCMAKE_BUILD_TYPE=Debug",
         "-DCMAKE_C_FLAGS=--coverage -O0", "-DCMAKE_EXE_LINKER_FLAGS=--coverage",
         "-DCMAKE_SHARED_LINKER_FLAGS=--coverage"], check=True)
    run(["cmake", "--build", build, "-j2"], check=True)
    for stale in build.rglob("*.gcda"):  # counts of an earlier run would inflate the result
        stale.unlink()
    tests = run(["ctest", "--test-dir", build, "--output-on-failure"], check=True)
    summary = next((l for l in tests.stdout.splitlines() if "tests passed" in l), "")
    gen = build / "generated"
    out = build / "coverage.json"
    # gcovr resolves gcov's working directory below --root: the folder holding both the sources and the build
    # (the clone for build/coverage; for an installed wheel, whatever holds its tree and the user's cache)
    root = Path(os.path.commonpath([tree, build.resolve()]))
    run([sys.executable, "-m", "gcovr", "--root", root, "--object-directory", build,
         "--filter", str(tree / "firmware_c" / "src"), "--filter", str(gen),
         "--json", str(out), str(build / "CMakeFiles" / "slipest_obj.dir")], check=True, cwd=root)
    version = run([sys.executable, "-m", "gcovr", "--version"]).stdout.splitlines()[0]
    data = json.loads(out.read_text())
    files = []
    for entry in data["files"]:
        path = Path(entry["file"])
        path = path if path.is_absolute() else root / path
        lines = [l for l in entry["lines"] if not l.get("gcovr/noncode", False)]
        # gcovr may list a line once per function instance; keep one record per line number
        by_line: dict[int, dict] = {}
        for l in lines:
            prev = by_line.get(l["line_number"])
            if prev is None or l["count"] > prev["count"]:
                by_line[l["line_number"]] = l
        n_br = sum(len(l.get("branches", [])) for l in by_line.values())
        hit_br = sum(1 for l in by_line.values() for b in l.get("branches", []) if b["count"] > 0)
        files.append(FileCoverage(
            name=rel(path, gen), lines=len(by_line), lines_hit=sum(1 for l in by_line.values() if l["count"] > 0),
            branches=n_br, branches_hit=hit_br,
            missed_lines=sorted(n for n, l in by_line.items() if l["count"] == 0)))
    files.sort(key=lambda f: f.name)
    return CoverageResult(files, summary, version)


def table(res: CoverageResult) -> str:
    rows = ["| File | Statements | Branches | Uncovered lines |", "|---|---:|---:|---|"]
    for f in res.files:
        lp = 100.0 * f.lines_hit / f.lines if f.lines else 100.0
        bp = 100.0 * f.branches_hit / f.branches if f.branches else 100.0
        missed = ", ".join(map(str, f.missed_lines[:30])) + (" …" if len(f.missed_lines) > 30 else "")
        rows.append(f"| {f.name} | {lp:.1f} % ({f.lines_hit}/{f.lines}) | {bp:.1f} % ({f.branches_hit}/{f.branches}) | {missed} |")
    hw = res.handwritten()
    rows.append(f"| **hand-written (src/*.c)** | **{hw.line_pct:.1f} %** | **{hw.branch_pct:.1f} %** | |")
    rows.append(f"| **total with generated codec** | **{res.line_pct:.1f} %** | **{res.branch_pct:.1f} %** | |")
    return "\n".join(rows)
