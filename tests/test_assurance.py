"""Flight-software assurance evidence (issue 16): bundle integrity at configure time, MISRA C:2012
(cppcheck addon) against the recorded deviations, static analysers, and C statement/branch coverage.

None of these skip: the tools come from scripts/apt-packages.txt (cppcheck, clang-tidy,
frama-c-base) and the test extras (gcovr); a missing tool fails the test naming its Debian package
(fleetlab.system_tools). Every analyser also has a negative control here: a planted defect it must report.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fleetlab.paths import repo_root
from doc_figures import assert_near, worst_case_instructions
from planted import planted_src

REPO = repo_root()

BUNDLE = REPO / "firmware_c" / "bundles" / "example"


def configure(build: Path, bundle: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["cmake", "-S", str(REPO), "-B", str(build), f"-DSLIPEST_BUNDLE={bundle}",
         f"-DPython3_EXECUTABLE={sys.executable}"],
        capture_output=True, text=True, timeout=300)


# --------------------------------------------------------------------------- 6b bundle hashes
def test_configure_accepts_the_untouched_bundle(tmp_path):
    bundle = tmp_path / "bundle"
    shutil.copytree(BUNDLE, bundle)
    proc = configure(tmp_path / "build", bundle)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "files match manifest.json sha256" in proc.stdout


def test_configure_rejects_a_header_edited_within_range(tmp_path):
    bundle = tmp_path / "bundle"
    shutil.copytree(BUNDLE, bundle)
    header = bundle / "slipest_model_q.h"
    text = header.read_text()
    # flip one weight digit: still a valid int8/int16 literal, so the compiler would accept it
    marker = text.index("_q_w1[")
    pos = next(i for i in range(text.index("{", marker), len(text)) if text[i] in "123456789")
    edited = text[:pos] + ("2" if text[pos] == "1" else "1") + text[pos + 1:]
    assert edited != text
    header.write_text(edited)
    proc = configure(tmp_path / "build", bundle)
    assert proc.returncode != 0
    err = proc.stderr
    assert "bundle hash mismatch" in err and "slipest_model_q.h" in err, err[-3000:]
    assert "re-export the bundle" in err


def test_configure_rejects_a_missing_listed_file(tmp_path):
    bundle = tmp_path / "bundle"
    shutil.copytree(BUNDLE, bundle)
    (bundle / "vectors.bin").unlink()
    proc = configure(tmp_path / "build", bundle)
    assert proc.returncode != 0
    assert "vectors.bin" in proc.stderr and "missing" in proc.stderr, proc.stderr[-3000:]


# --------------------------------------------------------------------------- 1 MISRA C:2012
@pytest.fixture(scope="module")
def misra_runs():
    """Two MISRA runs at once over the same tree (as `fleetlab assure` in two terminals, or two CI jobs)."""
    from fleetlab.assurance import misra
    from fleetlab.assurance.sources import concurrently

    return concurrently([lambda: misra.run_cppcheck(BUNDLE), lambda: misra.run_cppcheck(BUNDLE)])


@pytest.fixture(scope="module")
def misra_findings(misra_runs):
    return misra_runs[0]


def test_misra_runs_at_once_agree_and_leave_the_sources_as_they_were(misra_runs):
    """cppcheck's addon writes a dump of each file it checks: beside the sources unless given a build folder, where
    a second run deleted the first one's dumps (the addon then checked nothing in them) and an installed wheel's
    read-only tree refused them. Each run now has its own folder: the two agree, and firmware_c/src keeps its files."""
    assert misra_runs[0] == misra_runs[1] and len(misra_runs[0][0]) > 0
    assert not [p.name for p in (REPO / "firmware_c" / "src").iterdir() if p.suffix in (".dump", ".ctu-info")]


def test_misra_findings_are_all_recorded_deviations(misra_findings):
    from fleetlab.assurance import misra

    res = misra.compare(misra_findings[0])
    assert res.total > 0, "the MISRA addon reported nothing: is it running at all?"
    assert not res.unrecorded, "unrecorded MISRA findings (fix them or add a permit): " + "; ".join(
        f"rule {r} in {f}: {n} found, {rec} recorded, lines {res.lines[(r, f)]}" for r, f, n, rec in res.unrecorded)
    # the record is exact for the library: a count above what is found would hide that many new findings
    assert not res.stale, "stale MISRA records (lower the counts): " + "; ".join(
        f"rule {r} in {f}: {n} found, {rec} recorded" for r, f, n, rec in res.stale)


def test_misra_checker_finds_a_stale_record_in_the_library_only(tmp_path, misra_findings):
    """A library count above what is found is stale; a bundle header's count above an SN-S header's is not
    (a layer-table header has more, MISRA_DEVIATIONS.md MD-2.3)."""
    from fleetlab.assurance import misra

    text = misra.deviations_file().read_text()
    row = "| 20.7 | firmware_c/src/slipest_infer_table_q.c | "
    start = text.index(row) + len(row)
    count = int(text[start:text.index(" ", start)])
    record = tmp_path / "MISRA_DEVIATIONS.md"
    record.write_text(text.replace(f"{row}{count} ", f"{row}{count + 1} "))
    res = misra.compare(misra_findings[0], record)
    assert [(r, f, n, rec) for r, f, n, rec in res.stale] == [("20.7", "firmware_c/src/slipest_infer_table_q.c", count, count + 1)]
    assert res.recorded[("2.3", "bundle/slipest_model_q.h")] > res.findings[("2.3", "bundle/slipest_model_q.h")]


def test_misra_checker_fails_on_an_unrecorded_deviation(tmp_path, misra_findings):
    """The checker can fail: drop one permit's rows and its section from a copy of the record."""
    from fleetlab.assurance import misra

    text = misra.deviations_file().read_text()
    trimmed = "\n".join(line for line in text.splitlines()
                        if not line.startswith("| 13.4 |") and not line.startswith("### MD-13.4"))
    record = tmp_path / "MISRA_DEVIATIONS.md"
    record.write_text(trimmed)
    res = misra.compare(misra_findings[0], record)
    assert [(r, f) for r, f, _, _ in res.unrecorded] == [("13.4", "firmware_c/src/slipest_node.c")]


# --------------------------------------------------------------------------- 4 coverage
def _with_a_failing_c_test(real_run):
    """coverage's `run`, adding one C test that fails (`false`) to the build's test list just before ctest runs
    (configure writes the list again, so the next measurement in the folder is clean)."""
    def run(cmd, **kwargs):
        if Path(str(cmd[0])).name == "ctest":
            build = Path(cmd[cmd.index("--test-dir") + 1])
            with open(build / "CTestTestfile.cmake", "a") as f:
                f.write(f'add_test(planted_failure "{shutil.which("false")}")\n')
        return real_run(cmd, **kwargs)
    return run


@pytest.fixture(scope="module")
def coverage_runs(tmp_path_factory):
    """Two coverage measurements, one after the other in one build folder outside the source tree (where
    FLEETLAB_BUILD_ROOT or a wheel's cache puts it): an SN-D bundle (layer-table) with one planted failing C test,
    then the example SN-S bundle. Two coverage builds, about 30 s on a 2-core machine (with the SN-D export)."""
    from fleetlab.assurance import coverage
    from fleetlab.export.bundle import export_bundle
    from fleetlab.export.vectors import draw_inputs
    from small_models import quick_model

    snd = tmp_path_factory.mktemp("coverage-snd") / "bundle"
    export_bundle(quick_model("sn-d"), snd, inputs=draw_inputs(1000, None, seed=3))
    build = tmp_path_factory.mktemp("coverage-outside-the-tree") / "coverage"
    assert not build.resolve().is_relative_to(REPO)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(coverage, "run", _with_a_failing_c_test(coverage.run))
        layer_table = coverage.measure(build, snd)
    return layer_table, coverage.measure(build, BUNDLE)


def test_c_tests_cover_the_library(coverage_runs):
    """gcov statement/branch coverage of src/*.c by ctest, from a build folder outside the source tree (before,
    gcovr got `--root /` there and ended in "maximum recursion depth exceeded"). The issue's goal is >= 95 %
    statements and >= 90 % branches; the floors here are what this branch's C tests reach (regressions fail)."""
    from fleetlab.assurance import coverage

    res = coverage_runs[1]
    assert "100% tests passed" in res.ctest_summary and not res.ctest_failure
    names = {f.name for f in res.files}
    assert {"firmware_c/src/slipest_node.c", "firmware_c/src/slipest_infer_q.c", "generated/slipest_dbc.c"} <= names
    hw = res.handwritten()
    # floors = what the C tests reach (98.8 % / 91.3 % with the model store and the CANopen node in the
    # library), minus a small margin; the goal is 95 % / 90 %. What stays uncovered and why:
    # docs/assurance.md
    assert hw.line_pct >= 98.5, coverage.table(res)
    assert hw.branch_pct >= 91.0, coverage.table(res)
    # every file the tests reach is listed with real counts (a broken gcov run gives zeros)
    assert all(f.lines > 0 and f.lines_hit > 0 for f in res.files), coverage.table(res)
    assert coverage.headline(res) == (f"{hw.line_pct:.1f} % statements, {hw.branch_pct:.1f} % branches "
                                      f"(goal 95 % / 90 %)", True)


def test_coverage_forgets_the_objects_of_an_earlier_configuration(coverage_runs):
    """The SN-S measurement after a layer-table one in the same folder counts only what the SN-S build compiles:
    before, the stale slipest_image_table.c.gcno was counted at 0 % (88.3 % statements, "FAIL")."""
    layer_table, sn_s = coverage_runs
    assert "firmware_c/src/slipest_image_table.c" in {f.name for f in layer_table.files}
    assert "firmware_c/src/slipest_image_table.c" not in {f.name for f in sn_s.files}
    assert sn_s.removed_stale > 0


def test_a_failing_c_test_is_recorded_not_raised(coverage_runs):
    """A failing ctest is a failed row with its names, and the coverage is still measured (before: RuntimeError
    "ctest exited 8", and no report)."""
    from fleetlab.assurance import coverage

    layer_table = coverage_runs[0]
    text, ok = coverage.ctest_line(layer_table)
    assert not ok and re.fullmatch(r"ctest: 1 of \d+ tests failed: planted_failure", text), text
    assert layer_table.handwritten().line_pct > 0


def test_layer_table_coverage_is_shown_and_not_held_to_the_goal(coverage_runs):
    """A layer-table bundle's coverage is measured and shown; the goal, held on SN-S bundles, is said not to apply
    (the store's, the node's and the model checks' C tests run on SN-S images only): no FAIL, no pass."""
    from fleetlab.assurance import coverage

    layer_table = coverage_runs[0]
    assert layer_table.layer_table
    text, ok = coverage.headline(layer_table)
    hw = layer_table.handwritten()
    assert ok is None
    assert text.startswith(f"{hw.line_pct:.1f} % statements, {hw.branch_pct:.1f} % branches (layer-table bundle")
    assert "applies to SN-S bundles only" in text


def _coverage_result(lines_hit: int, branches_hit: int, **fields):
    """A coverage result of 1000 statements and 1000 branches in src/*.c and a codec far below the goal."""
    from fleetlab.assurance.coverage import CoverageResult, FileCoverage

    return CoverageResult([FileCoverage("firmware_c/src/slipest_node.c", 1000, lines_hit, 1000, branches_hit),
                           FileCoverage("generated/slipest_dbc.c", 500, 300, 100, 30)],
                          "100% tests passed, 0 tests failed out of 17", "gcovr 8.8", **fields)


def _name(fn, name):
    fn.__name__ = name
    return fn


@pytest.fixture
def fast_checks(monkeypatch):
    """The report's MISRA, analyser and stack checks replaced by instant clean results, so that a test of what
    `assure` does with the coverage check's result takes a second, not minutes."""
    from fleetlab.assurance import analysers, misra, stack

    monkeypatch.setattr(misra, "check", lambda bundle=None: misra.compare([]))
    for fn in ("clang_tidy", "gcc_analyzer", "strict_warnings"):
        monkeypatch.setattr(analysers, fn, _name(lambda bundle=None, fn=fn: analysers.ToolResult(fn, version="x"), fn))
    monkeypatch.setattr(stack, "analyse", lambda bundle, q_only: ([], []))


def _report(tmp_path, capsys) -> tuple[int, str, str, str]:
    """`fleetlab assure` without EVA and the CPU targets: exit status, assurance.md, stdout, stderr."""
    from fleetlab.cli import main

    code = main(["assure", "--bundle", str(BUNDLE), "--out", str(tmp_path / "report"), "--no-eva", "--no-target"])
    out, err = capsys.readouterr()
    md = tmp_path / "report" / "assurance.md"
    return code, md.read_text() if md.exists() else "", out, err


COVERAGE_CASES = {
    # src/*.c above the goal, the codec far below it: pass (before, `assure coverage` printed the total with the
    # codec, 85.9 % "(goal 95.0)", and exited 0 while the report said 98.8 % pass)
    "above": ((988, 913), {}, "98.8 % statements, 91.3 % branches (goal 95 % / 90 %)", "pass", 0),
    # below the goal: FAIL and exit 1, in the report and alone (before: exit 0, and the report's FAIL beside
    # "Gating checks: all pass")
    "below": ((940, 913), {}, "94.0 % statements, 91.3 % branches (goal 95 % / 90 %)", "FAIL", 1),
    # a layer-table bundle: measured, shown, not held to the goal
    "layer-table": ((610, 496), {"layer_table": True}, "61.0 % statements, 49.6 % branches (layer-table bundle: "
                    "measured, not held to the goal, which applies to SN-S bundles only", "—", 0),
}


@pytest.mark.parametrize("case", sorted(COVERAGE_CASES))
def test_coverage_has_one_headline_in_the_report_and_alone(case, tmp_path, capsys, monkeypatch, fast_checks):
    """`fleetlab assure coverage` and the report give the same figure, the same verdict and the same exit status."""
    from fleetlab.assurance import coverage
    from fleetlab.cli import main

    (lines, branches), fields, text, verdict, status = COVERAGE_CASES[case]
    monkeypatch.setattr(coverage, "measure", lambda build, bundle=None: _coverage_result(lines, branches, **fields))
    assert main(["assure", "--bundle", str(BUNDLE), "coverage", "--build", str(tmp_path / "b")]) == status
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith(f"Coverage by the C tests (src/*.c): {text}"), last
    assert last.endswith("" if verdict == "—" else f": {verdict}"), last
    code, md, out, err = _report(tmp_path, capsys)
    assert code == status and not err, err
    row = next(l for l in md.splitlines() if l.startswith("| Coverage by the C tests (src/*.c) |"))
    assert row.startswith(f"| Coverage by the C tests (src/*.c) | {text}") and row.endswith(f"| {verdict} |"), row
    assert row in out  # the terminal shows the report's summary
    assert ("Gating checks: all pass." in md) == (status == 0)


def test_a_failing_check_is_a_row_of_the_report_and_the_others_are_kept(tmp_path, capsys, monkeypatch, fast_checks):
    """A check whose tool fails (here the coverage build: a command exiting 8) and a failing C test are FAIL rows
    with their reasons; every other check is still in the report; the command exits 1 with one summary line and
    no traceback (before: the RuntimeError's traceback, and no report)."""
    from fleetlab.assurance import coverage, sources

    monkeypatch.setattr(coverage, "measure", lambda build, bundle=None: sources.run(
        ["sh", "-c", "echo 'coverage.c:1: error: planted' >&2; exit 8"], check=True))
    code, md, out, err = _report(tmp_path, capsys)
    assert code == 1 and not err, err
    assert ("| Coverage by the C tests (src/*.c) | did not finish: sh exited 8: coverage.c:1: error: planted | FAIL |"
            in md)
    assert "| MISRA C:2012 (cppcheck addon) | 0 findings in 0 rules, 0 unrecorded | pass |" in md
    assert "| No recursion (call-graph cycle check) | acyclic | pass |" in md
    assert "Gating checks: FAILED, 1 of 7: Coverage by the C tests (src/*.c)." in out.splitlines()

    monkeypatch.setattr(coverage, "measure", lambda build, bundle=None: _coverage_result(
        988, 913, ctest_failure="ctest: 1 of 18 tests failed: planted_failure"))
    code, md, out, err = _report(tmp_path, capsys)
    assert code == 1 and not err, err
    assert "| C tests (ctest, host build with coverage) | ctest: 1 of 18 tests failed: planted_failure | FAIL |" in md
    assert "| Coverage by the C tests (src/*.c) | 98.8 % statements, 91.3 % branches (goal 95 % / 90 %) | pass |" in md
    assert "Gating checks: FAILED, 1 of 8: C tests (ctest, host build with coverage)." in out.splitlines()


def _failing(stderr: str, stdout: str = ""):
    """A stand-in for sources.run: every command exits 1 with this output."""
    from fleetlab.host_tools.firmware.build import Result

    return lambda cmd, **kwargs: Result([str(c) for c in cmd], 1, stdout, stderr)


def test_a_tool_that_fails_is_one_line_not_a_traceback(tmp_path, capsys, monkeypatch):
    """cppcheck, Frama-C, a build step, and a missing FPU-less target are the project's one-line error
    (FleetlabError) with the line that says why; `fleetlab assure CHECK` prints that line and exits 2."""
    from fleetlab.assurance import analysers, coverage, misra, report, sources
    from fleetlab.cli import main
    from fleetlab.errors import FleetlabError

    with monkeypatch.context() as mp:
        mp.setattr(misra, "run", _failing("cppcheck: error: unrecognized command line option\nmore"))
        with pytest.raises(FleetlabError, match=r"^cppcheck exited 1: cppcheck: error: unrecognized command line "
                                                r"option$"):
            misra.run_cppcheck(BUNDLE)
    with monkeypatch.context() as mp:
        mp.setattr(analysers, "run", _failing("[kernel] User Error: stopping\n[kernel] Frama-C aborted: invalid user input."))
        with pytest.raises(FleetlabError, match=r"^frama-c on eva_\w+ exited 1: \[kernel\] User Error: stopping$"):
            analysers.frama_c_eva(BUNDLE, entries=["eva_features"])
    with monkeypatch.context() as mp:
        mp.setattr(report.target_registry, "discover", lambda: {})
        with pytest.raises(FleetlabError, match="no ARM target without an FPU"):
            report.soft_float_target()
    with pytest.raises(FleetlabError, match=r"^python\S* exited 3: last words$"):
        sources.run([sys.executable, "-c", "import sys; print('noise'); print('last words', file=sys.stderr); sys.exit(3)"],
                    check=True)

    monkeypatch.setattr(coverage, "measure", lambda build, bundle=None: sources.run(
        ["cmake", "--build", str(tmp_path / "nowhere")], check=True))
    assert main(["assure", "--bundle", str(BUNDLE), "coverage", "--build", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fleetlab assure: error: cmake --build exited 1: "), err


# --------------------------------------------------------------------------- 2 static analysers
@pytest.mark.parametrize("tool", ["strict_warnings", "gcc_analyzer", "clang_tidy"])
def test_static_analyser_is_clean(tool):
    from fleetlab.assurance import analysers

    res = getattr(analysers, tool)(BUNDLE)
    assert res.version, f"{tool}: no version string, tool did not run"
    assert res.clean, f"{res.name}:\n" + "\n".join(res.findings)


@pytest.fixture(scope="module")
def eva(tmp_path_factory):
    """The EVA analyses of this file, side by side (each is one single-threaded Frama-C process, the
    extractor's about 40 s): the library as it is, and the two controls with a planted defect."""
    from fleetlab.assurance import analysers
    from fleetlab.assurance.sources import concurrently

    # without the saturation that states |e| < 2^14 (a bound that holds only through e's relation to max|d|)
    kernel = planted_src(tmp_path_factory.mktemp("kernel"), "slipest_infer_q.c",
                         "int32_t e = SAT(rsr_h(NH * SAT(h[i], 25) - sum, k2_half, k2), 14);",
                         "int32_t e = rsr_h(NH * SAT(h[i], 25) - sum, k2_half, k2);")
    # without the 64-bit widening of S * S in the variance of a closed window
    features = planted_src(tmp_path_factory.mktemp("features"), "slipest_features.c",
                           "uint64_t d = (uint64_t)(nn * q - (int64_t)s * s);",
                           "uint64_t d = (uint64_t)(nn * q - s * s);")
    clean, (planted_kernel,), (planted_features,) = concurrently([
        lambda: analysers.frama_c_eva(BUNDLE),
        lambda: analysers.frama_c_eva(BUNDLE, entries=["eva_infer_q"], src_dir=kernel),
        lambda: analysers.frama_c_eva(BUNDLE, entries=["eva_features"], src_dir=features)])
    return {e.entry: e for e in clean}, planted_kernel, planted_features


def test_frama_c_eva_over_all_int16_inputs(eva):
    """EVA, a sound value analysis: no alarm on the kernel nor on the feature extraction, for every int16
    input at once."""
    res = eva[0]
    assert set(res) == {"eva_infer_q", "eva_features"}
    assert res["eva_features"].alarms == [], "\n".join(res["eva_features"].alarms)
    assert window_features_reached(res["eva_features"].log)  # the zero covers the window-closing path
    infer = res["eva_infer_q"]
    assert "Frama_C_show_each_class: {0; 1; 2}" in infer.log  # the analysis ran through the whole kernel
    assert infer.alarms == [], "\n".join(infer.alarms)


def test_frama_c_eva_finds_an_overflow(eva):
    """The kernel's zero is not vacuous: without the saturation that states |e| < 2^14 (a bound that holds
    only through e's relation to max|d|), EVA reports the possible overflow of e * e."""
    res = eva[1]
    assert any("e * e" in a for a in res.alarms), "\n".join(res.alarms)


# planted defects, one scratch file each, put among the library's sources: each analyser must report its own
# (a configuration that turns every check off, or a changed output format, would read as clean)
PLANTED = {
    # bugprone-suspicious-memset-usage: value and size swapped, so nothing is cleared
    "clang_tidy": ("#include <stdint.h>\n#include <string.h>\nvoid clear(int32_t *v, int n);\n"
                   "void clear(int32_t *v, int n) { memset(v, n, 0); }\n",
                   ["bugprone-suspicious-memset-usage"]),
    # a double fclose and a use after free
    "gcc_analyzer": ("#include <stdio.h>\n#include <stdlib.h>\nint twice(const char *path);\nint after(int n);\n"
                     "int twice(const char *path) {\n  FILE *f = fopen(path, \"r\");\n  if (f == NULL) return -1;\n"
                     "  (void)fclose(f);\n  return fclose(f);\n}\n"
                     "int after(int n) {\n  int *p = malloc(sizeof *p);\n  if (p == NULL) return -1;\n  *p = n;\n"
                     "  free(p);\n  return *p;\n}\n",
                     ["-Wanalyzer-double-fclose", "-Wanalyzer-use-after-free"]),
}


@pytest.mark.parametrize("tool", sorted(PLANTED))
def test_static_analyser_reports_a_planted_defect(tool, tmp_path, monkeypatch):
    """Negative control: the same call that finds the library clean reports the planted defect."""
    from fleetlab.assurance import analysers

    text, expected = PLANTED[tool]
    bad = tmp_path / "planted.c"
    bad.write_text(text)
    monkeypatch.setattr(analysers, "library_sources", lambda: [bad])
    res = getattr(analysers, tool)(BUNDLE)
    assert not res.clean
    for check in expected:
        assert any("planted.c" in f and check in f for f in res.findings), (check, res.findings)


def window_features_reached(log: str) -> bool:
    """The driver's reachability marker (eva_driver.c): EVA printed the values slipest_window_features_q
    returns for a window the extractor closed, 0 (features computed) among them. Without it, "no alarm"
    could mean that EVA decided no window ever closes and never analysed the feature code."""
    for values in re.findall(r"Frama_C_show_each_window_features: (\S+)", log):
        if values.startswith("{") and 0 in {int(v) for v in values.strip("{}").split(";")}:
            return True
        m = re.fullmatch(r"\[(-?\d+)\.\.(-?\d+)\]", values)
        if m and int(m[1]) <= 0 <= int(m[2]):
            return True
    return False


def test_frama_c_eva_finds_an_overflow_in_the_feature_extractor(eva):
    """Negative control of the extractor's proof: with the 64-bit widening of S * S removed from the variance
    of a closed window, EVA reports the signed overflow (reached only through a closed window)."""
    res = eva[2]
    assert window_features_reached(res.log)
    assert any("slipest_features.c" in a and "overflow" in a and "s * s" in a for a in res.alarms), \
        "\n".join(res.alarms)


def test_static_analyser_can_fail(tmp_path, monkeypatch):
    """The warning check sees a defect: a file with a sign conversion among the sources fails it."""
    from fleetlab.assurance import analysers

    bad = tmp_path / "bad.c"
    bad.write_text("#include <stdint.h>\nuint32_t f(int32_t x);\nuint32_t f(int32_t x) { return x; }\n")
    monkeypatch.setattr(analysers, "library_sources", lambda: [bad])
    res = analysers.strict_warnings(BUNDLE)
    assert not res.clean and any("Wsign-conversion" in f for f in res.findings), res.findings


# --------------------------------------------------------------------------- 3 stack bounds
def test_stack_bounds_cover_the_call_graph_without_recursion():
    from fleetlab.assurance import stack

    rows, cycles = stack.analyse(BUNDLE, q_only=True)
    assert cycles == []
    worst = {r.function: r for r in rows}
    # the node's worst path runs through the inference kernel, so its bound contains it
    node, infer = worst["slipest_node_handle"], worst["slipest_infer_q"]
    assert "slipest_infer_q" in node.chain and node.bytes > infer.bytes > 0
    assert not node.dynamic and not infer.dynamic


def test_stack_cycle_check_finds_recursion():
    from fleetlab.assurance.stack import StackGraph

    g = StackGraph(frame={"a": 8, "b": 16, "c": 4}, calls={"a": {"b"}, "b": {"c"}, "c": {"a"}})
    assert g.cycles() == [["a", "b", "c", "a"]]
    g.calls["c"] = set()
    assert g.cycles() == [] and g.worst("a")[0] == 28


def test_bundle_files_are_keyed_alike_wherever_the_bundle_lives(tmp_path):
    """The deviations table keys the model headers as bundle/<name>: a bundle exported inside the clone
    (the demo's demo_out/bundle) or outside it must map onto the same keys, or its findings look unrecorded."""
    from fleetlab.assurance.sources import rel

    inside = REPO / "build" / "test-rel-bundle"
    for d in (inside, tmp_path / "b"):
        d.mkdir(parents=True, exist_ok=True)
        (d / "manifest.json").write_text("{}")
        (d / "slipest_model_q.h").write_text("")
        assert rel(d / "slipest_model_q.h") == "bundle/slipest_model_q.h"
    assert rel(REPO / "firmware_c" / "src" / "slipest_node.c") == "firmware_c/src/slipest_node.c"


# --------------------------------------------------------------------------- 3 worst-case instruction counts
def test_worst_case_instruction_counts_on_the_reference_target():
    """The QEMU worst-case image runs every case and the maxima are consistent with the call structure:
    the node's worst frame closes a window (features + inference + frames), so it costs more than one
    inference, and one push costs far less than an inference."""
    from fleetlab.assurance import wcet

    desc, rows = wcet.measure(REPO / "build" / "test-wcet")
    by = {(r.function, r.cases.split(":")[0]): r for r in rows}
    assert all(r.n_cases > 0 and r.instructions > 0 for r in rows), wcet.table(rows)
    infer_vec = by[("slipest_infer_q", "bundle vectors")]
    assert infer_vec.n_cases >= 100  # every bundle vector, not a sample of them
    worst = wcet.per_function(rows)
    assert worst["slipest_node_handle"] > worst["slipest_infer_q"] > 4 * worst["slipest_extractor_push"] > 0, \
        wcet.table(rows)
    # each maximum within +-10 % of the figure docs/assurance.md publishes (a rise fails until the docs say so)
    published = worst_case_instructions()
    assert set(published) == set(worst), (published, worst)
    for fn, n in worst.items():
        assert_near(n, published[fn], f"worst-case instructions of {fn}")


def test_worst_case_parser_rejects_incomplete_output():
    from fleetlab.assurance import wcet

    with pytest.raises(ValueError, match="calib_ticks"):
        wcet.parse("calib_instructions=2000000\nreps=16\n")


def test_assure_runs_one_check_as_a_subcommand(capsys):
    """`fleetlab assure stack` is the stack check alone (it replaced `python -m fleetlab.assurance.stack`)."""
    from fleetlab.cli import main

    assert main(["assure", "--bundle", str(BUNDLE), "stack"]) == 0
    out = capsys.readouterr().out
    assert "call graph acyclic: no recursion" in out and "| slipest_infer_q |" in out


def test_assure_refuses_mixed_or_missing_options(capsys):
    from fleetlab.cli import main

    assert main(["assure"]) == 1
    assert "--out DIR is required for the report" in capsys.readouterr().err
    assert main(["assure", "--out", "x", "--no-eva", "stack"]) == 1
    assert "--out, --no-eva: options of the full report, not of 'assure stack'" in capsys.readouterr().err


@pytest.mark.parametrize("check", [None, "misra", "stack"])
def test_assure_refuses_a_broken_bundle_in_one_line(tmp_path, capsys, check):
    """A bundle with an edited file, or an ONNX-only one, is one line before any tool runs (before, the report
    ended in a compiler's traceback and `assure misra` counted what cppcheck could parse of a half-model)."""
    from fleetlab.cli import main

    edited = tmp_path / "edited"
    shutil.copytree(BUNDLE, edited)
    header = edited / "slipest_model_q.h"
    header.write_text(header.read_text().replace("#include", "#include  ", 1))  # two bytes more
    onnx_only = tmp_path / "onnx_only"
    onnx_only.mkdir()
    manifest = json.loads((BUNDLE / "manifest.json").read_text())
    manifest.pop("quantization")
    manifest["files"] = {}
    (onnx_only / "manifest.json").write_text(json.dumps(manifest))
    for bundle, message in ((edited, f"slipest_model_q.h: {header.stat().st_size} bytes, manifest.json says "
                                       f"{header.stat().st_size - 2} (truncated or edited)"), (onnx_only, "an ONNX-only bundle has no C model")):
        args = ["assure", "--bundle", str(bundle), *(["--out", str(tmp_path / "report")] if check is None else [check])]
        assert main(args) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "report").exists()
