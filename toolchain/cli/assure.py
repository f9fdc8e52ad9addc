"""`fleetlab assure`: the evidence report, or one check of it.

    fleetlab assure --out DIR [--bundle DIR] [--fuzz-stats FILE] [--no-eva] [--no-target]   every check, one report
    fleetlab assure misra|analysers|coverage|stack|wcet [--bundle DIR] ...                     one check, printed

The checks are functions of fleetlab.assurance; this module only reads options and prints results.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from fleetlab.host_tools.firmware import targets as target_registry

from ..assurance import analysers, coverage, misra, stack, wcet
from ..assurance.report import COVERAGE_ROW, CTEST_ROW, assure, checked_bundle
from ..paths import build_root, default_bundle
from ..errors import InputError

__all__ = ["add_arguments", "run"]

REPORT_ONLY = ("out", "fuzz_stats", "no_eva", "no_target")


def _misra(args: argparse.Namespace) -> int:
    res = misra.check(args.bundle)
    if args.table:
        print(misra.counts_table(res))
        return 0
    print(f"{res.version}: {res.total} MISRA findings in {len(res.by_rule())} rules; "
          f"{len(res.unrecorded)} unrecorded (rule, file) keys; {len(res.stale)} stale records")
    for rule, file, n, rec in res.unrecorded:
        print(f"UNRECORDED rule {rule} in {file}: {n} found, {rec} recorded; lines {res.lines[(rule, file)]}")
    for rule, file, n, rec in res.stale:
        print(f"stale record rule {rule} in {file}: {n} found, {rec} recorded (lower the count)")
    return 1 if res.unrecorded else 0


def _analysers(args: argparse.Namespace) -> int:
    status = 0
    for fn in (analysers.strict_warnings, analysers.gcc_analyzer, analysers.clang_tidy):
        r = fn(args.bundle)
        print(f"{r.name}: {len(r.findings)} findings ({r.seconds:.1f} s)")
        for f in r.findings:
            print("  " + f)
        status |= not r.clean
    if args.eva:
        for e in analysers.frama_c_eva(args.bundle):
            print(f"frama-c eva {e.entry}: {len(e.alarms)} alarms ({e.seconds:.1f} s)")
            for a in e.alarms:
                print("  " + a)
    return status


def _coverage(args: argparse.Namespace) -> int:
    res = coverage.measure(args.build or build_root() / "coverage", args.bundle)
    print(coverage.table(res))
    # the report's two rows: the same figures, the same verdicts, and the exit status that goes with them
    tests, tests_ok = coverage.ctest_line(res)
    print(f"{CTEST_ROW}: {tests}: {'pass' if tests_ok else 'FAIL'}")
    text, ok = coverage.headline(res)
    print(f"{COVERAGE_ROW}: {text}" + ("" if ok is None else f": {'pass' if ok else 'FAIL'}"))
    return 1 if ok is False or not tests_ok else 0


def _stack(args: argparse.Namespace) -> int:
    rows, cycles = stack.analyse(args.bundle, q_only=not args.full)
    if cycles:
        print("RECURSION: " + "; ".join(" → ".join(c) for c in cycles))
        return 1
    print("call graph acyclic: no recursion")
    print(stack.table(rows))
    return 0


def _wcet(args: argparse.Namespace) -> int:
    name = args.target or target_registry.reference().name
    desc, rows = wcet.measure(args.build or build_root() / f"wcet-{name}", args.bundle, args.target)
    print(f"Worst-case instruction counts on {desc} (qemu -icount, measured maximum, not a bound):")
    print(wcet.table(rows))
    return 0


# name -> (handler, one-line help, module whose docstring describes the check)
CHECKS = {
    "misra": (_misra, "MISRA C:2012 (cppcheck addon) against firmware_c/MISRA_DEVIATIONS.md; exit 1 on an unrecorded finding", misra),
    "analysers": (_analysers, "clang-tidy, gcc -fanalyzer and the strict warnings (and Frama-C EVA with --eva); exit 1 on a finding", analysers),
    "coverage": (_coverage, "statement and branch coverage of the C library by ctest (gcov); exit 1 below the goal or on "
                            "a failing C test", coverage),
    "stack": (_stack, "worst-case stack of every public entry point and the no-recursion proof; exit 1 on recursion", stack),
    "wcet": (_wcet, "worst-case instruction counts under qemu -icount on a SysTick CPU target", wcet),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bundle", type=Path, default=None, help="export bundle (default: the example bundle)")
    report = p.add_argument_group("the full report (no CHECK named)")
    report.add_argument("--out", type=Path, default=None, help="directory for assurance.md / assurance.html (required)")
    report.add_argument("--fuzz-stats", type=Path, default=None,
                        help="fuzz-stats.json of the last campaign (default: build/fuzz-long, else build/fuzz)")
    report.add_argument("--no-eva", action="store_true", help="skip Frama-C EVA")
    report.add_argument("--no-target", action="store_true",
                        help="skip the Cortex-M3/M4 builds (float-free archive check, measured stack and cost)")
    sub = p.add_subparsers(dest="check", metavar="CHECK", help="run one check and print its result instead of the report")
    for name, (_, help_text, module) in CHECKS.items():
        c = sub.add_parser(name, help=help_text, description=module.__doc__.split("\n\n")[0],
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        # SUPPRESS: `fleetlab assure --bundle B misra` keeps B (a subparser default would overwrite it)
        c.add_argument("--bundle", type=Path, default=argparse.SUPPRESS, help="export bundle (default: the example bundle)")
        if name == "misra":
            c.add_argument("--table", action="store_true", help="print the findings as a deviations counts table")
        elif name == "analysers":
            c.add_argument("--eva", action="store_true", help="also run Frama-C EVA")
        elif name == "coverage":
            c.add_argument("--build", type=Path, default=None,
                           help="coverage build directory (default: coverage/ under the build root: build/ in a clone)")
        elif name == "stack":
            c.add_argument("--full", action="store_true", help="the full library (float path too) instead of slipest_q")
        elif name == "wcet":
            c.add_argument("--target", default=None, help="SysTick CPU target (default: the reference target)")
            c.add_argument("--build", type=Path, default=None, help="cross build directory (default: build/wcet-TARGET)")


def run(args: argparse.Namespace) -> int:
    if args.check is not None:
        # a broken bundle is one line before the check runs: it would otherwise fail inside its compiler or,
        # worse, report on what it could parse (MISRA's counts of a half-built model); the report checks it itself
        args.bundle = checked_bundle(args.bundle or default_bundle())
        given = [f"--{k.replace('_', '-')}" for k in REPORT_ONLY if getattr(args, k) not in (None, False)]
        if given:
            raise InputError(f"{', '.join(given)}: options of the full report, not of 'assure {args.check}'")
        return CHECKS[args.check][0](args)
    if args.out is None:
        raise InputError("--out DIR is required for the report (or name one check: " + ", ".join(CHECKS) + ")")
    return assure(args.bundle, args.out, fuzz_stats=args.fuzz_stats, eva=not args.no_eva, target=not args.no_target)
