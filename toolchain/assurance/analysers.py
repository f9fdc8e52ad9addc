"""Static analysers over the slipest library: clang-tidy (clang-analyzer, bugprone, cert; the
configuration and its disabled checks are in firmware_c/.clang-tidy), gcc -fanalyzer, the strict
warning set, and Frama-C EVA (sound value analysis) through firmware_c/eva/eva_driver.c.

    fleetlab assure analysers [--bundle DIR] [--eva]
"""
from __future__ import annotations

import re
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from .sources import ToolFailed, concurrently, fw, generate_dbc, gist, include_dirs, library_sources, need, rel, run

STRICT_WARNINGS = ["-Wall", "-Wextra", "-pedantic", "-Wconversion", "-Wsign-conversion", "-Wcast-align",
                   "-Wshadow", "-Wstrict-prototypes"]
# EVA entry points of the driver, the library files each one needs (the kernel's model included: without
# its definition EVA stops at the first read of the model) and the precision options of each
EVA_TARGETS = {
    # precision 5 unrolls the 30 layer-1 rows, so each partial sum is bounded with its own row's weights
    "eva_infer_q": (["slipest_infer_q.c", "slipest_infer_table_q.c", "slipest_bundle_q.c"], ["-eva-precision", "5"]),
    # the driver's stream loop is unrolled (eva_driver.c): no widening of the window sums
    "eva_features": (["slipest_features.c"], ["-eva-precision", "1", "-eva-split-return", "auto"]),
}
EVA_OPTIONS = ["-machdep", "x86_32"]

@dataclass
class ToolResult:
    name: str
    findings: list[str] = field(default_factory=list)
    seconds: float = 0.0
    version: str = ""
    note: str = ""

    @property
    def clean(self) -> bool:
        return not self.findings


def _with_sources(bundle: Path, fn):
    with tempfile.TemporaryDirectory() as tmp:
        gen = generate_dbc(Path(tmp) / "generated", bundle)
        incs = [f"-I{d}" for d in include_dirs(bundle, gen.parent)]
        return fn([*library_sources(), gen], incs, gen.parent)


def _gcc(flags: list[str], name: str, bundle: Path) -> ToolResult:
    gcc = need("gcc")
    t0 = time.perf_counter()

    def go(files, incs, gen):
        out = ToolResult(name, version=run([gcc, "--version"]).stdout.splitlines()[0])
        for f in files:
            res = run([gcc, "-std=c99", "-O2", "-c", "-o", "/dev/null", *incs, *flags, f])
            for line in (res.stdout + res.stderr).splitlines():
                if re.search(r": (warning|error):", line):
                    out.findings.append(line.replace(str(f), rel(f, gen)))
        return out

    out = _with_sources(bundle, go)
    out.seconds = time.perf_counter() - t0
    return out


def strict_warnings(bundle: Path | None = None) -> ToolResult:
    return _gcc(STRICT_WARNINGS, "gcc " + " ".join(STRICT_WARNINGS[3:]), bundle)


def gcc_analyzer(bundle: Path | None = None) -> ToolResult:
    return _gcc(["-fanalyzer"], "gcc -fanalyzer", bundle)


def clang_tidy(bundle: Path | None = None) -> ToolResult:
    tidy = need("clang-tidy")
    t0 = time.perf_counter()

    def go(files, incs, gen):
        res = run([tidy, "-quiet", f"--config-file={fw() / '.clang-tidy'}", *files, "--", "-std=c99", *incs])
        out = ToolResult("clang-tidy (clang-analyzer-*, bugprone-*, cert-*)",
                         version=run([tidy, "--version"]).stdout.strip().splitlines()[-1].strip())
        out.findings = [l for l in (res.stdout + res.stderr).splitlines() if re.search(r": (warning|error):", l)]
        if res.returncode != 0 and not out.findings:
            out.findings.append(f"clang-tidy exited {res.returncode}: {res.stderr[-500:]}")
        return out

    out = _with_sources(bundle, go)
    out.seconds = time.perf_counter() - t0
    return out


@dataclass
class EvaResult:
    entry: str
    alarms: list[str]
    seconds: float
    log: str


def frama_c_eva(bundle: Path | None = None, entries: list[str] | None = None,
                options: list[str] | None = None, src_dir: Path | None = None) -> list[EvaResult]:
    """Alarms of EVA per driver entry point (fixed-point library: -DSLIPEST_Q_ONLY). src_dir: where the
    library sources are read from (the tests give a modified copy to show that EVA finds a defect)."""
    frama = need("frama-c")

    def one(entry: str, incs: list[str]) -> EvaResult:
        names, precision = EVA_TARGETS[entry]
        srcs = [(src_dir or fw() / "src") / name for name in names]
        t0 = time.perf_counter()
        res = run([frama, "-no-autoload-plugins", "-load-module", "eva", *(options or EVA_OPTIONS + precision),
                   f"-cpp-extra-args={' '.join(incs)} -DSLIPEST_Q_ONLY", fw() / "eva" / "eva_driver.c", *srcs,
                   "-eva", "-main", entry], timeout=3600)
        text = res.stdout + res.stderr
        if res.returncode != 0 or f"done for function {entry}" not in text:
            why = (f"exited {res.returncode}: {gist(res.stderr, res.stdout)}" if res.returncode
                   else f"the analysis stopped before its end (no 'done for function {entry}')")
            raise ToolFailed(f"frama-c on {entry} {why}", text[-3000:])
        alarms = []
        # each message starts with "[eva...]"; an alarm is "[eva:alarm] FILE:LINE: Warning:" + indented text
        for chunk in re.split(r"\n(?=\[)", text):
            m = re.match(r"\[eva:alarm\] (\S+?):(\d+): Warning: *\n(.*)", chunk, re.S)
            if m:
                alarms.append(f"{Path(m[1]).name}:{m[2]}: {' '.join(m[3].split())}")
        return EvaResult(entry, alarms, time.perf_counter() - t0, text)

    def go(files, incs, gen):  # the entries are separate analyses: they run side by side
        return concurrently([lambda e=e: one(e, incs) for e in entries or list(EVA_TARGETS)])

    return _with_sources(bundle, go)
