"""``fleetlab assure --bundle DIR --out DIR``: run every assurance check on one bundle and write
one evidence report (OUT/assurance.md and OUT/assurance.html) built only from what the tools
printed in this run (plus the statistics file of the last long fuzz campaign, named in the report).
Exit status 1 when a gating check fails, i.e. when any row of the report's summary says FAIL: bundle
hashes, float-free archive, unrecorded MISRA findings, a finding of clang-tidy / gcc -fanalyzer / the strict
warnings, an EVA alarm, recursion, a stack bound below the measured peak, coverage below its goal on an SN-S
bundle or a failing C test, a crash in the last fuzz campaign. A check whose tool fails (a build, ctest, gcovr,
cppcheck, Frama-C) is recorded as such a row with the line that says why; the other checks are still reported.

The tools run first, side by side (`measure_all`); then each entry of `CHECKS` turns their results into its
part of the report (`Part`: summary rows, each gating or not, and its sections), in the report's order.
"""
from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from fleetlab.export.bundle import load_bundle
from fleetlab.host_tools.firmware import targets as target_registry
from fleetlab.host_tools.firmware.measure import target_costs
from fleetlab.host_tools.firmware.build import cmake_build
from . import analysers, coverage, misra, stack, wcet
from ..errors import FleetlabError, InputError, first_line
from ..paths import build_root, default_bundle, in_clone, repo_root
from .sources import concurrently, gist, need, run, tool_version


def default_fuzz_stats() -> list[Path]:
    return [build_root() / "fuzz-long" / "fuzz-stats.json", build_root() / "fuzz" / "fuzz-stats.json"]


def _section(title: str, body: str) -> str:
    return f"## {title}\n\n{body.strip()}\n"


def bundle_hashes(bundle: Path) -> tuple[bool, str, str]:
    manifest = bundle / "manifest.json"
    data = json.loads(manifest.read_text())
    rows, ok = ["| File | sha256 (manifest) | matches |", "|---|---|---|"], True
    for name, entry in sorted(data.get("files", {}).items()):
        if "sha256" not in entry:
            continue
        path = bundle / name
        got = hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else "missing"
        match = got == entry["sha256"]
        ok &= match
        rows.append(f"| {name} | `{entry['sha256'][:16]}…` | {'yes' if match else 'NO (' + got[:16] + ')'} |")
    return ok, hashlib.sha256(manifest.read_bytes()).hexdigest(), "\n".join(rows)


def checked_bundle(bundle: Path) -> Path:
    """The bundle, once it is known to be whole and to have a C model: a missing, truncated or edited file,
    or an ONNX-only export, is one line here rather than a compiler's error inside some analyser."""
    if load_bundle(bundle).qparams is None:
        raise InputError(f"{bundle}: an ONNX-only bundle has no C model to check (export it without --onnx-only)")
    return bundle


COVERAGE_ROW = "Coverage by the C tests (src/*.c)"
CTEST_ROW = "C tests (ctest, host build with coverage)"


def gating_line(failing: list[str], rows: int) -> str:
    """The report's verdict in one line: every row that says FAIL, named."""
    if not failing:
        return "Gating checks: all pass."
    return f"Gating checks: FAILED, {len(failing)} of {rows}: {'; '.join(failing)}."


def soft_float_target() -> target_registry.Target:
    """The ARM target without an FPU that builds both libraries (the issue's float-free check is on its
    fixed-point archive: a float helper there would reach a user who links it on an FPU-less core)."""
    for t in target_registry.discover().values():
        if not t.fpu and not t.integer_only and t.compiler == "arm-none-eabi-gcc":
            return t
    raise FleetlabError("no ARM target without an FPU in firmware_c/cmake (the float-free check needs one): "
                        "reinstall fleetlab, or run `fleetlab assure --no-target`")


def float_free(build_m3: Path, description: str) -> tuple[bool, str]:
    res = run(["ctest", "--test-dir", build_m3, "-R", "softfloat", "-V"])
    lines = [l.split(": -- ", 1)[-1] for l in res.stdout.splitlines() if "soft-float helper symbols" in l]
    nm = run(["arm-none-eabi-nm", build_m3 / "libslipest_q.a"]).stdout
    hits = sorted(set(re.findall(r"\b(__aeabi_[fd]\w*)", nm)))
    ok = res.returncode == 0 and not hits
    body = "\n".join(f"- {l.strip()}" for l in lines)
    body += f"\n- `arm-none-eabi-nm libslipest_q.a` ({description}): {len(hits)} `__aeabi_f*`/`__aeabi_d*` symbols"
    body += (": " + ", ".join(hits)) if hits else ""
    return ok, body


def target_evidence(bundle: Path) -> tuple[target_registry.Target, tuple[bool, str], dict, tuple]:
    """The cross builds' evidence: the FPU-less ARM target and the float-free check of its archive, and on
    the reference target the measured cost and stack (`target_costs`) and the worst-case instructions (wcet)."""
    work = build_root() / "assure"
    soft = soft_float_target()
    cmake_build(work / soft.name, bundle, target=soft)
    free = float_free(work / soft.name, soft.description)
    ref = target_registry.reference()
    cmake_build(work / ref.name, bundle, target=ref)
    return soft, free, target_costs(ref.name, work / ref.name), wcet.measure(work / ref.name, bundle)


def required_tools(eva: bool, target: bool) -> list[str]:
    """Every host tool a run of assure calls, so that a missing one stops it before the long work (the
    target builds' compilers and emulators are checked beside it)."""
    tools = ["cmake", "ctest", "gcc", "gcov", "cppcheck", "clang-tidy", "arm-none-eabi-gcc"]
    if eva:
        tools.append("frama-c")
    if target:
        tools.append("arm-none-eabi-nm")
    return tools


@dataclass
class CheckFailed:
    """A check that could not finish (its build, ctest, gcovr, cppcheck or Frama-C failed): the one line that
    says why, and the tail of the tool's output for the report."""
    check: str
    reason: str
    output: str = ""


# what a check raises when one of its tools fails (sources.ToolFailed, the build driver's OSError, a parser's
# ValueError); the report records it as a failed check and keeps the others. A bug still shows its traceback.
CHECK_ERRORS = (FleetlabError, OSError, ValueError, RuntimeError, subprocess.SubprocessError)


def guarded(name: str, call):
    """`call`, returning CheckFailed instead of raising one of CHECK_ERRORS."""
    def run_check():
        try:
            return call()
        except CHECK_ERRORS as e:
            rest = "\n".join(str(e).splitlines()[1:])
            output = getattr(e, "output", "") or rest
            reason = first_line(e)
            if rest and not getattr(e, "output", ""):  # the build driver's OSError: its command, then the output
                reason += f": {gist(rest)}"
            return CheckFailed(name, reason, output[-3000:])
    return run_check


def _output_block(output: str) -> str:
    """A failed tool's output as a code block after its reason ("" when it printed nothing)."""
    return f"\n\n```\n{output.strip()}\n```\n" if output.strip() else ""


def _failed_section(title: str, failed: CheckFailed) -> str:
    return _section(title, f"**FAILED** (the check did not finish): {failed.reason}" + _output_block(failed.output))


@dataclass(frozen=True)
class Row:
    """One row of the report's summary; ok None: shown, not gating (a row that says FAIL fails the report)."""
    item: str
    result: str
    ok: bool | None

    @property
    def gating(self) -> bool:
        return self.ok is not None

    def markdown(self) -> str:
        result = self.result.replace("|", "\\|")  # a tool's line may hold one: it would split the table's cell
        return f"| {self.item} | {result} | {'pass' if self.ok else ('—' if self.ok is None else 'FAIL')} |"


@dataclass
class Part:
    """What one check adds to the report: its summary rows and its sections (Markdown, in order)."""
    rows: list[Row] = field(default_factory=list)
    sections: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Evidence:
    """What the checks read: the bundle, the options, and every tool's result (or CheckFailed) by name."""
    bundle: Path
    done: dict
    eva: bool
    target: bool
    fuzz_stats: Path | None


def did_not_finish(item: str, title: str, failed: CheckFailed) -> Part:
    return Part([Row(item, f"did not finish: {failed.reason}", False)], [_failed_section(title, failed)])


def measure_all(bundle: Path, eva: bool, target: bool) -> dict:
    """Every tool's result by name (CheckFailed where its tool failed). The tools are independent, each in its
    own folder: they run side by side (a 2-core machine takes the report in about half the time), the longest
    first. The functions are looked up here, when the report runs, so that a test can stand in for a tool."""
    calls = {"eva": lambda: analysers.frama_c_eva(bundle)} if eva else {}
    if target:
        calls["target"] = lambda: target_evidence(bundle)
    calls.update({
        "misra": lambda: misra.check(bundle),
        **{fn.__name__: (lambda fn=fn: fn(bundle))
           for fn in (analysers.clang_tidy, analysers.gcc_analyzer, analysers.strict_warnings)},
        "coverage": lambda: coverage.measure(build_root() / "assure" / "coverage", bundle),
        "stack_q": lambda: stack.analyse(bundle, q_only=True),
        "stack_full": lambda: stack.analyse(bundle, q_only=False),
    })
    return dict(zip(calls, concurrently([guarded(name, call) for name, call in calls.items()])))


def bundle_check(ev: Evidence) -> Part:
    ok, manifest_hash, rows = bundle_hashes(ev.bundle)
    return Part([Row("Bundle hashes (manifest.json)", f"manifest sha256 `{manifest_hash[:16]}…`", ok)],
                [_section("Bundle", f"Bundle: `{ev.bundle}`\n\nmanifest.json sha256: `{manifest_hash}`\n\n{rows}")])


def float_free_check(ev: Evidence) -> Part:
    """The target builds: the FPU-less target's archive holds no soft-float helper."""
    if not ev.target:
        return Part()
    if isinstance(ev.done["target"], CheckFailed):
        return did_not_finish("Float-free fixed-point archive, measured stack and cost (CPU target builds)",
                              "Float-free check", ev.done["target"])
    soft, (ok, body), _, _ = ev.done["target"]
    return Part([Row(f"Float-free fixed-point archive ({soft.description})",
                     "0 soft-float symbols" if ok else "soft-float found", ok)], [_section("Float-free check", body)])


def misra_check(ev: Evidence) -> Part:
    m = ev.done["misra"]
    if isinstance(m, CheckFailed):
        return did_not_finish("MISRA C:2012 (cppcheck addon)", "MISRA C:2012", m)
    row = Row("MISRA C:2012 (cppcheck addon)", f"{m.total} findings in {len(m.by_rule())} rules, "
              f"{len(m.unrecorded)} unrecorded", not m.unrecorded)
    by_rule = "\n".join(f"| {r} | {n} |" for r, n in sorted(m.by_rule().items(), key=lambda kv: misra._rule_key(kv[0])))
    unrec = "\n".join(f"- rule {r} in {f}: {n} found, {rec} recorded" for r, f, n, rec in m.unrecorded) or "none"
    return Part([row], [_section("MISRA C:2012", f"{m.version}; deviations: `firmware_c/MISRA_DEVIATIONS.md` "
                                 f"(one permit per rule).\n\n| Rule | Findings |\n|---|---:|\n{by_rule}\n\n"
                                 f"Unrecorded findings: {unrec}\n\nOther cppcheck findings (style, not gating): "
                                 f"{len(m.other)}\n\n" + "\n".join(f"- {o}" for o in m.other))])


def static_analysis_check(ev: Evidence) -> Part:
    """The analysers and Frama-C EVA: one section, a row per analyser and per EVA entry."""
    part = Part()
    rows = ["| Analyser | Findings | Seconds |", "|---|---:|---:|"]
    details = []
    for name, label in (("strict_warnings", "gcc strict warnings"), ("gcc_analyzer", "gcc -fanalyzer"),
                        ("clang_tidy", "clang-tidy")):
        r = ev.done[name]
        if isinstance(r, CheckFailed):
            rows.append(f"| {label} | did not finish | |")
            part.rows.append(Row(label, f"did not finish: {r.reason}", False))
            details.append(f"- {label} FAILED: {r.reason}" + _output_block(r.output))
            continue
        rows.append(f"| {r.name} | {len(r.findings)} | {r.seconds:.1f} |")
        part.rows.append(Row(r.name, f"{len(r.findings)} findings", r.clean))
        details += [f"- {f}" for f in r.findings]
    eva_text = "Frama-C EVA skipped (--no-eva)."
    if ev.eva and isinstance(ev.done["eva"], CheckFailed):
        failed = ev.done["eva"]
        part.rows.append(Row("Frama-C EVA", f"did not finish: {failed.reason}", False))
        eva_text = f"**FAILED** (the analysis did not finish): {failed.reason}" + _output_block(failed.output)
    elif ev.eva:
        entries = ev.done["eva"]
        eva_rows = ["| EVA entry (all int16 inputs) | Alarms | Seconds |", "|---|---:|---:|"]
        alarm_rows = [f"- {e.entry}: `{a}`" for e in entries for a in e.alarms]
        for e in entries:
            eva_rows.append(f"| {e.entry} | {len(e.alarms)} | {e.seconds:.1f} |")
            part.rows.append(Row(f"Frama-C EVA {e.entry}", f"{len(e.alarms)} alarms", not e.alarms))
        options = "; ".join(f"{entry}: `{' '.join(analysers.EVA_OPTIONS + opts)}`"
                            for entry, (_, opts) in analysers.EVA_TARGETS.items())
        eva_text = (f"{tool_version(['frama-c', '-version'])}, driver `firmware_c/eva/eva_driver.c`, options: "
                    f"{options}.\n\n" + "\n".join(eva_rows) + "\n\nAlarms (each a possible runtime error "
                    "EVA could not exclude for some input):\n\n" + ("\n".join(alarm_rows) or "none"))
    part.sections.append(_section("Static analysis", "\n".join(rows) + "\n\n" + ("\n".join(details) or "No findings.")
                                  + "\n\n### Frama-C EVA\n\n" + eva_text))
    return part


def _measured(ev: Evidence) -> dict:
    """The reference target's measured cost and stack ({} without the target builds, or where they failed)."""
    result = ev.done.get("target")
    return {} if result is None or isinstance(result, CheckFailed) else result[2]


def stack_check(ev: Evidence) -> Part:
    """No recursion, the worst-case stack of both libraries, and the cost image's wrappers' bounds against the
    peak the target build measured."""
    stack_failed = next((ev.done[k] for k in ("stack_q", "stack_full") if isinstance(ev.done[k], CheckFailed)), None)
    if stack_failed:
        return did_not_finish("No recursion (call-graph cycle check)", "Worst-case stack", stack_failed)
    rows_q, cycles = ev.done["stack_q"]
    rows_full, cycles_full = ev.done["stack_full"]
    no_rec = not cycles and not cycles_full
    part = Part([Row("No recursion (call-graph cycle check)", "acyclic" if no_rec else f"cycles: {cycles + cycles_full}",
                     no_rec)])
    worst = {r.function: r.bytes for r in rows_q}
    body = "Frames from `-fstack-usage -fcallgraph-info=su` (arm-none-eabi-gcc, Cortex-M4 flags of the target build).\n\n"
    measured = _measured(ev)
    # the painter measures a wrapper in the cost image: compare the wrapper's bound with it
    harness = guarded("stack_bench", lambda: stack.bench_bounds(ev.bundle))() if measured else None
    if isinstance(harness, CheckFailed):
        part.rows.append(Row("Stack bounds of the cost image's wrappers", f"did not finish: {harness.reason}", False))
        body += f"**FAILED** (the wrappers' bounds): {harness.reason}" + _output_block(harness.output) + "\n\n"
    elif measured:
        cmp_rows = ["| Entry (cost-image wrapper) | Entry bound | Wrapper bound (bytes) | Measured peak, painted (bytes) "
                    "| bound >= measured |", "|---|---:|---:|---:|---|"]
        for fn, key in (("slipest_infer_q", "stack_q"), ("slipest_node_handle", "stack_node_window")):
            ok = harness[key] >= measured[key]
            cmp_rows.append(f"| {fn} ({stack.BENCH_WRAPPERS[key]}) | {worst[fn]} | {harness[key]} | {measured[key]:.0f} "
                            f"| {'yes' if ok else 'NO'} |")
            part.rows.append(Row(f"Stack bound {fn}", f"{worst[fn]} B; with the bench wrapper {harness[key]} B bound vs "
                                 f"{measured[key]:.0f} B measured", ok))
        body += "\n".join(cmp_rows) + "\n\n"
    body += "### Fixed-point library (slipest_q)\n\n" + stack.table(rows_q)
    body += "\n\n### Full library (with the float path)\n\n" + stack.table(rows_full[:6])
    part.sections.append(_section("Worst-case stack", body))
    return part


def execution_cost_check(ev: Evidence) -> Part:
    """The measured worst-case instructions on the reference target (shown, not gating: a measured maximum)."""
    measured = _measured(ev)
    if not measured:
        return Part()
    desc, wc = ev.done["target"][3]
    worst_fn = wcet.per_function(wc)
    return Part([Row(f"Worst-case instructions ({desc}, measured maximum)",
                     ", ".join(f"{fn} {n:.0f}" for fn, n in worst_fn.items()), None)],
                [_section(f"Execution cost ({desc}, QEMU icount)",
                          "Worst case: the maximum MEASURED over the bundle vectors and over inputs built to "
                          "reach the long paths (cases in `firmware_c/target/wcet_target.c`), each case timed "
                          "over repeated identical calls; a measured maximum, not a static bound. Command: "
                          "`fleetlab assure wcet`.\n\n" + wcet.table(wc) +
                          f"\n\nAverage over the bench loop of the vectors (fleetlab bench c): slipest_infer_q "
                          f"{measured['q']:.0f} instructions per inference; SLCAN parsing + slipest_node_handle "
                          f"{measured['node_instructions_per_sample']:.0f} instructions per telemetry sample (3 frames).")])


def coverage_check(ev: Evidence) -> Part:
    """One figure, one verdict (coverage.headline), as `fleetlab assure coverage` prints them."""
    cov = ev.done["coverage"]
    if isinstance(cov, CheckFailed):
        return did_not_finish(COVERAGE_ROW, "Coverage", cov)
    held = (f"The figure held to the goal ({coverage.goal()}) is the hand-written library's (src/*.c) on an "
            f"SN-S bundle; the generated codec is listed apart."
            if not cov.layer_table else f"This is a {coverage.LAYER_TABLE_NOTE}.")
    return Part([Row(CTEST_ROW, *coverage.ctest_line(cov)), Row(COVERAGE_ROW, *coverage.headline(cov))],
                [_section("Coverage", f"{cov.gcovr_version}; ctest: {cov.ctest_summary.strip()}"
                          + (f" ({cov.ctest_failure})" if cov.ctest_failure else "") + f"\n\n{held}\n\n"
                          + coverage.table(cov))])


def fuzzing_check(ev: Evidence) -> Part:
    """The statistics file of the last fuzz campaign (scripts/fuzz.sh): gating where there is one."""
    stats_file = ev.fuzz_stats or next((p for p in default_fuzz_stats() if p.exists()), None)
    if not (stats_file and stats_file.exists()):
        return Part([Row("Fuzzing", "no fuzz-stats.json found (run scripts/fuzz.sh --long)", None)])
    st = json.loads(stats_file.read_text())
    # a long-mode file merges campaigns of several dates: each target carries its own date, clean flag and
    # source (older files have none of these; "-" then)
    frows = ["| Target | Executions | Seconds | Date | Clean | Source |", "|---|---:|---:|---|---|---|"]
    frows += [f"| {t} | {v['executions']:,} | {v['seconds']} | {v.get('date', '-')} | "
              f"{'-' if 'clean' not in v else ('yes' if v['clean'] else 'CRASH')} | {v.get('source', '-')} |"
              for t, v in st["targets"].items()]
    fewest = min(v["executions"] for v in st["targets"].values())
    return Part([Row("Fuzzing (last campaign, ASan+UBSan)", f"{st['mode']} run {st['date']}, "
                     f"min {fewest:,} executions/target, {'clean' if st['clean'] else 'CRASH'}", st["clean"])],
                [_section("Fuzzing", f"From `{stats_file}` (written by scripts/fuzz.sh).\n\n" + "\n".join(frows))])


def versions_check(ev: Evidence) -> Part:
    """The version of every tool the evidence came from (no row: nothing to pass or fail)."""
    cov = ev.done["coverage"]
    gcovr = (tool_version([sys.executable, "-m", "gcovr", "--version"]) if isinstance(cov, CheckFailed)
             else cov.gcovr_version)
    versions = {
        "gcc": tool_version(["gcc", "--version"]), "arm-none-eabi-gcc": tool_version(["arm-none-eabi-gcc", "--version"]),
        "clang": tool_version(["clang", "--version"]), "clang-tidy": tool_version(["clang-tidy", "--version"]).strip(),
        "cppcheck": tool_version(["cppcheck", "--version"]), "frama-c": tool_version(["frama-c", "-version"]),
        "gcovr": gcovr, "cmake": tool_version(["cmake", "--version"]),
        "qemu-system-arm": tool_version(["qemu-system-arm", "--version"]),
    }
    return Part(sections=[_section("Toolchain versions", "\n".join(f"- {k}: {v}" for k, v in versions.items()))])


# The report, in order: each check's rows go to the summary, its sections after it.
CHECKS = (bundle_check, float_free_check, misra_check, static_analysis_check, stack_check, execution_cost_check,
          coverage_check, fuzzing_check, versions_check)


def source_commit() -> str:
    """What names the sources the evidence is of: the clone's commit (and whether it has uncommitted changes),
    or the installed wheel's version."""
    if not in_clone():
        from .. import __version__

        return f"`fleetlab {__version__} wheel, {repo_root()}`"
    commit = run(["git", "-C", repo_root(), "rev-parse", "HEAD"]).stdout.strip()
    dirty = bool(run(["git", "-C", repo_root(), "status", "--porcelain", "--untracked-files=no"]).stdout.strip())
    return f"`{commit}`" + (" (with uncommitted changes)" if dirty else "")


def write_report(out: Path, parts: list[Part], seconds: float) -> list[str]:
    """OUT/assurance.md and .html from the checks' parts; prints the summary; returns the failing rows' items."""
    rows = [r for p in parts for r in p.rows]
    failing = [r.item for r in rows if r.ok is False]
    head = (f"# slipest assurance evidence\n\nGenerated by `fleetlab assure` in {seconds:.0f} s "
            f"on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; source commit {source_commit()}.\n\n"
            f"## Summary\n\n| Check | Result | Status |\n|---|---|---|\n" + "\n".join(r.markdown() for r in rows)
            + f"\n\n{gating_line(failing, sum(r.gating for r in rows))}\n")
    md = head + "\n" + "\n".join(s for p in parts for s in p.sections)
    (out / "assurance.md").write_text(md)
    import markdown
    html = markdown.markdown(md, extensions=["tables"])
    (out / "assurance.html").write_text(f"<!doctype html><meta charset='utf-8'><title>slipest assurance</title>"
                                        f"<style>body{{font-family:sans-serif;max-width:70em;margin:auto}}"
                                        f"td,th{{border:1px solid #ccc;padding:2px 6px}}table{{border-collapse:collapse}}"
                                        f"</style>{html}")
    print(head)
    print(f"report: {out / 'assurance.md'} and assurance.html")
    return failing


def assure(bundle: Path | None, out: Path, *, fuzz_stats: Path | None = None, eva: bool = True,
           target: bool = True) -> int:
    """Run every check on `bundle` (default: the example bundle), write OUT/assurance.md and .html; 1 when a
    gating check fails (every row of the summary that says FAIL). A check whose tool fails (a build, ctest,
    cppcheck, Frama-C) is such a row, with its reason; the other checks are still run and reported. `eva=False`
    skips Frama-C EVA, `target=False` the cross builds (float-free archive, measured cost)."""
    for tool in required_tools(eva, target):
        need(tool)
    if target:
        for t in (soft_float_target(), target_registry.reference()):
            t.need_tools(f"fleetlab assure (the {t.name} build; --no-target skips it)")
    bundle = checked_bundle((bundle or default_bundle()).resolve())  # a broken bundle: one line, before any tool
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    ev = Evidence(bundle, measure_all(bundle, eva, target), eva, target, fuzz_stats)
    parts = [check(ev) for check in CHECKS]
    return 1 if write_report(out, parts, time.perf_counter() - t_start) else 0
