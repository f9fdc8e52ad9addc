"""CPU targets: the registry (one file per target under firmware_c/cmake/), the CMake/QEMU driver,
and every new target's ctest under QEMU: all bundle vectors bit-exact, the node's transmitted frames
byte-identical to the x86-64 golden file (the big-endian property), no soft-float helpers in the
integer-only archives and images. (Cortex-M3/M4 run in tests/test_firmware.py.)"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fleetlab.cli import bench_c
from fleetlab.host_tools.firmware import build, figures, targets
from fleetlab.paths import repo_root
from doc_figures import assert_near
from doc_figures import target_costs as published_costs
from required import need_tools, path_without

REPO = repo_root()

BUNDLE = REPO / "firmware_c" / "bundles" / "example"
GOLDEN = REPO / "firmware_c" / "tests" / "golden" / "node_frames_example.txt"
CO_GOLDEN = REPO / "firmware_c" / "tests" / "golden" / "co_frames_example.txt"
NEW_TARGETS = ["powerpc", "sparc-leon3", "riscv32", "cortex-m0", "cortex-m7"]
# issue 15: the ONNX->C compiler emx-onnx-cgen took this many instructions per float inference of the
# same model on the M4 (-O3); fleetlab's float path must stay below it on every target with an FPU
EMX_ONNX_CGEN_F32_INSTRUCTIONS = 5_704


def _list(capsys, monkeypatch, extra_dir: Path | None = None) -> dict:
    if extra_dir is not None:
        monkeypatch.setenv(targets.ENV_DIRS, str(extra_dir))
    parser = argparse.ArgumentParser()
    bench_c.add_arguments(parser)
    assert bench_c.run(parser.parse_args(["--list-targets", "--json"])) == 0
    return json.loads(capsys.readouterr().out)


def test_registry_lists_every_target_file(capsys, monkeypatch):
    monkeypatch.delenv(targets.ENV_DIRS, raising=False)
    found = _list(capsys, monkeypatch)
    files = sorted(p.stem for p in (REPO / "firmware_c" / "cmake").glob("*.cmake")
                   if re.search(r"^set\(SLIPEST_TARGET_NAME ", p.read_text(), re.M))
    assert sorted(found) == files  # each target file is named after its target
    assert {"cortex-m3", "cortex-m4", *NEW_TARGETS} <= set(found)
    assert found["powerpc"]["endian"] == "big" and found["powerpc"]["qemu_mode"] == "user"
    assert found["sparc-leon3"]["endian"] == "big" and found["sparc-leon3"]["qemu_mode"] == "system"  # bare metal
    assert found["cortex-m0"]["integer_only"] and not found["cortex-m0"]["fpu"]
    assert found["cortex-m4"]["qemu_machine"] == "mps2-an386" and targets.reference().name == "cortex-m4"


def test_a_new_target_file_is_discovered_without_other_changes(tmp_path, capsys, monkeypatch):
    toy = tmp_path / "toy-cpu.cmake"
    toy.write_text("\n".join([
        "# fleetlab CPU target: a throw-away one",
        "set(SLIPEST_TARGET_NAME toy-cpu)",
        'set(SLIPEST_TARGET_DESCRIPTION "Toy CPU (test only)")',
        "set(SLIPEST_TARGET_COMPILER toy-gcc)",
        "set(SLIPEST_TARGET_ENDIAN big)", "set(SLIPEST_TARGET_FPU OFF)", "set(SLIPEST_TARGET_INTEGER_ONLY ON)",
        "set(SLIPEST_TARGET_QEMU qemu-system-toy)", "set(SLIPEST_TARGET_QEMU_MODE system)",
        "set(SLIPEST_TARGET_QEMU_MACHINE toyboard)", "set(SLIPEST_TARGET_REPORT semihosting)",
        "set(SLIPEST_TARGET_VECTORS embed)", "set(SLIPEST_TARGET_COUNTER none)", ""]))
    found = _list(capsys, monkeypatch, tmp_path)
    assert found["toy-cpu"]["qemu_machine"] == "toyboard" and found["toy-cpu"]["endian"] == "big"
    assert "cortex-m4" in found  # the repo's targets are still there
    # a broken record is an error that names the file and the missing key, not a silent drop
    toy.write_text(toy.read_text().replace("set(SLIPEST_TARGET_ENDIAN big)\n", ""))
    with pytest.raises(targets.TargetError, match=r"toy-cpu.cmake.*SLIPEST_TARGET_ENDIAN"):
        targets.discover()


def test_figure_keys_come_from_the_reference_target():
    """bench c keys the reference target's figures by its `key` (m4_* for cortex-m4); keys are distinct."""
    found = targets.discover()
    assert targets.reference().key == "m4"
    assert len({t.key for t in found.values()}) == len(found)
    assert all(re.fullmatch(r"[a-z0-9_]+", t.key) for t in found.values())


def test_no_cpu_is_named_in_code_outside_the_registry():
    """Only the target files (and tests/docs) name a CPU or its QEMU board."""
    names = set()
    for t in targets.discover().values():
        names.add(t.name)
        if t.qemu_machine not in ("none", "virt"):
            names.add(t.qemu_machine)
    pattern = re.compile("|".join(re.escape(n) for n in sorted(names)))
    offenders = []
    for folder in ("toolchain", "host_tools", "export"):
        for path in (REPO / folder).rglob("*.py"):
            if path.name == "targets.py":
                continue
            for i, line in enumerate(path.read_text().splitlines(), 1):
                if pattern.search(line):
                    offenders.append(f"{path.relative_to(REPO)}:{i}: {line.strip()}")
    assert not offenders, "\n".join(offenders)


# --------------------------------------------------------------------------- QEMU runs
def _need(t: targets.Target) -> None:
    need_tools(*t.tools)  # skips outside CI, fails under FLEETLAB_REQUIRE_TOOLS, naming the package


@pytest.fixture(scope="module")
def cross_builds(tmp_path_factory):
    return {"root": tmp_path_factory.mktemp("targets"), "done": {}}


def _built(cross_builds, name: str) -> tuple[targets.Target, Path]:
    t = targets.get(name)
    _need(t)
    if name not in cross_builds["done"]:
        cross_builds["done"][name] = build.cmake_build(cross_builds["root"] / name, BUNDLE, target=t)
    return t, cross_builds["done"][name]


@pytest.mark.parametrize("name", NEW_TARGETS)
def test_target_runs_every_vector_bit_exact_and_sends_the_x86_frames(cross_builds, name):
    t, bdir = _built(cross_builds, name)
    out = build.ctest(bdir)
    assert "100% tests passed" in out
    n = int(np.load(BUNDLE / "vectors.npz")["inputs"].shape[0])
    passes = re.findall(rf"vectors={n} q_fail=0 f32_fail=0 extractor_fail=0 model=\w+ PASS", out)
    # fixed-point image everywhere, plus the full (float) image where the target has the float path
    assert len(passes) == (1 if t.integer_only else 2), out[-3000:]
    for test, golden in (("node_frames", GOLDEN), ("co_frames", CO_GOLDEN)):  # plain and CANopen profiles
        assert re.search(rf"{test}_golden_{re.escape(name)} \.+ +Passed", out)
        assert f"identical to {golden}" in out
    for what in ("slipest_test_q.elf", "libslipest_q.a"):
        assert f"{what}: 0 soft-float helper symbols (expected absent)" in out


def test_golden_comparison_can_fail(cross_builds, tmp_path):
    """The frame comparison run on the big-endian PowerPC image reports one changed character of the golden file."""
    t, bdir = _built(cross_builds, "powerpc")
    lines = GOLDEN.read_text().splitlines(keepends=True)
    lines[5] = lines[5].replace("|", "0|", 1)
    bad = tmp_path / "golden.txt"
    bad.write_text("".join(lines))
    cmd = build.qemu_command(bdir, bdir / "slipest_node_frames.elf")
    res = subprocess.run(["cmake", f"-DRUN={';'.join(cmd)}", f"-DGOLDEN={bad}", "-P",
                          str(REPO / "firmware_c" / "cmake" / "compare_output.cmake")],
                         capture_output=True, text=True, timeout=120)
    msg = " ".join(res.stderr.split())  # CMake wraps its messages
    assert res.returncode != 0 and "output differs from" in msg and "at line 5:" in msg, msg


def test_big_endian_arm_compiles_and_links(cross_builds):
    """Big-endian ARM has no emulator here: the library, vectors reader, node and test images must
    build and link as big-endian code, and the archive/image soft-float checks pass."""
    t, bdir = _built(cross_builds, "cortex-r5-be")
    assert t.endian == "big" and not t.runs
    rec = build.run_record(bdir)
    readelf = rec["nm"].replace("-nm", "-readelf")
    for image in ("slipest_test_q.elf", "slipest_node_frames.elf"):
        head = subprocess.run([readelf, "-h", str(bdir / image)], capture_output=True, text=True).stdout
        assert "big endian" in head, head
    out = build.ctest(bdir)
    assert "slipest_test_q.elf: 0 soft-float helper symbols (expected absent)" in out


def test_soft_float_check_catches_rv32_float_code(cross_builds, tmp_path):
    """The archive/image check that guards the integer-only RISC-V build flags float code compiled for
    the same rv32imc core (RISC-V's helpers are __addsf3/__mulsf3..., not __aeabi_*): it can fail."""
    t, bdir = _built(cross_builds, "riscv32")
    src = tmp_path / "f.c"
    src.write_text("float scale(float a, float b) { return a * b + 1.0f; }\n")
    obj = tmp_path / "f.o"
    subprocess.run([t.compiler, "-march=rv32imc", "-mabi=ilp32", "-O2", "-c", str(src), "-o", str(obj)], check=True)
    check = REPO / "firmware_c" / "cmake" / "check_softfloat.cmake"
    nm = build.run_record(bdir)["nm"]

    def verdict(expect: str) -> subprocess.CompletedProcess:
        return subprocess.run(["cmake", f"-DNM={nm}", f"-DIMAGE={obj}", f"-DEXPECT={expect}", "-P", str(check)],
                              capture_output=True, text=True)

    bad = verdict("absent")
    assert bad.returncode != 0 and "__mulsf3" in bad.stderr and "__addsf3" in bad.stderr
    assert verdict("present").returncode == 0


@pytest.mark.parametrize("name", ["powerpc", "riscv32", "sparc-leon3", "cortex-m0", "cortex-m7"])
def test_bench_counts_instructions_as_published(cross_builds, name):
    """`bench c --target` figures: the exec trace (user-mode PowerPC, bare-metal SPARC), minstret under
    -icount (RISC-V), SysTick (M0, M7); each within +-10 % of the figure docs/integrating_slipest.md
    publishes for the target; integer-only targets have no float figure."""
    t, bdir = _built(cross_builds, name)
    row = figures.target_figures(t, bdir)
    doc = published_costs()[name]
    assert_near(row["instructions_per_inference_q"], doc["q"], f"{name} instructions per fixed-point inference")
    assert_near(row["instructions_per_sample_node_slcan"], doc["sample"], f"{name} instructions per sample")
    assert (row["instructions_per_inference_f32"] is None) == t.integer_only == (doc["f32"] is None)
    if not t.integer_only:
        assert_near(row["instructions_per_inference_f32"], doc["f32"], f"{name} instructions per float inference")
    if t.fpu:
        assert row["instructions_per_inference_f32"] < EMX_ONNX_CGEN_F32_INSTRUCTIONS, row
    assert 0 < row["stack_bytes_q"] <= row["stack_bytes_node_window"] < 4096
    assert 1_000 < row["flash_bytes_kernel_and_model"] < row["flash_bytes_can_node"]


def test_a_slow_phase_is_timed_over_the_calls_that_fit_the_counter():
    """A phase times fewer calls than the empty loop where its full count would wrap the counter
    (bench_target.c calls_that_fit; the 24-bit SysTick wrapped three times under 1,024 soft-float SN-D
    inferences on the M3 and showed 80,059 instructions instead of 1.39 million): the loop overhead is
    taken per call; a phase of which not one call fits is refused by name, not printed."""
    from fleetlab.host_tools.firmware.measure import costs_from_counts

    counts = {"calib_instructions": 2_000_000, "calib_ticks": 50_000, "inferences": 1024, "empty_ticks": 2048,
              "q_calls": 1024, "q_ticks": 2048 + 1024 * 70, "f32_calls": 3, "f32_ticks": 6 + 3 * 50_000,
              "node_99_samples_ticks": 99 * 100, "stack_q": 200, "stack_f32": 300, "stack_node_window": 500,
              "node_bytes": 700}
    costs = costs_from_counts("cortex-m3", counts, counts)
    assert costs["q"] == 70 * 40 and costs["f32"] == 50_000 * 40 and costs["node_instructions_per_sample"] == 4000
    with pytest.raises(ValueError, match="cortex-m3: one f32 inference takes more than half"):
        costs_from_counts("cortex-m3", counts, {**counts, "f32_calls": 0})


# --------------------------------------------------------------------------- required tools
def test_a_missing_emulator_fails_the_configure_naming_its_package(tmp_path):
    """CMake refuses a target whose QEMU is missing (it would register none of its QEMU tests), naming the
    package, unless the build asks for no emulator."""
    env = {**os.environ, "PATH": path_without("qemu-ppc", tmp_path / "bin")}
    cmd = build.configure_command(tmp_path / "b", BUNDLE, target=targets.get("powerpc"))
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    msg = " ".join(res.stderr.split())
    assert res.returncode != 0 and "qemu-ppc not found: install the Debian package qemu-user" in msg, msg[-2000:]
    res = subprocess.run([*cmd, "-DSLIPEST_ALLOW_NO_EMULATOR=ON"], capture_output=True, text=True, env=env,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]


@pytest.mark.parametrize("required", [True, False])
def test_a_missing_emulator_fails_the_target_tests_in_ci(tmp_path, required):
    """The PowerPC run with qemu-ppc stripped from PATH: under FLEETLAB_REQUIRE_TOOLS=1 (CI) a failure naming
    the package qemu-user, not a skip; outside CI a skip that says what to install."""
    env = {**os.environ, "PATH": path_without("qemu-ppc", tmp_path / "bin"), "FLEETLAB_REQUIRE_TOOLS": str(int(required))}
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                          f"{Path(__file__)}::test_target_runs_every_vector_bit_exact_and_sends_the_x86_frames[powerpc]"],
                         capture_output=True, text=True, env=env, cwd=REPO, timeout=600)
    out = " ".join(res.stdout.split())
    assert "qemu-ppc not found on PATH: install the Debian package qemu-user" in out, out[-3000:]
    if required:
        assert res.returncode == 1 and "1 failed" in out and "FLEETLAB_REQUIRE_TOOLS is set" in out, out[-3000:]
    else:
        assert res.returncode == 0 and "1 skipped" in out, out[-3000:]


def test_only_a_core_that_can_trap_unaligned_access_builds_for_the_trap(tmp_path):
    """SLIPEST_TARGET_UNALIGNED_TRAP in a target file is the one record of which cores have CCR.UNALIGN_TRP: the
    ARMv7-M ones. CMake refuses -DSLIPEST_TRAP_UNALIGNED=ON for another target, and so does `bench c` (one
    line, before any build); tests/test_export_arch.py runs the M4 built for the trap."""
    found = targets.discover()
    assert {n for n, t in found.items() if t.unaligned_trap} == {"cortex-m3", "cortex-m4", "cortex-m7"}
    cmd = build.configure_command(tmp_path / "b", BUNDLE, target=targets.get("riscv32"),
                                  options={"SLIPEST_TRAP_UNALIGNED": "ON", "SLIPEST_ALLOW_NO_EMULATOR": "ON"})
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    msg = " ".join(res.stderr.split())
    assert res.returncode != 0 and "target riscv32 has no unaligned-access trap" in msg, msg[-2000:]
    res = subprocess.run([sys.executable, "-m", "fleetlab.cli", "bench", "c", "--trap-unaligned", "--target", "powerpc",
                          "--build-dir", str(tmp_path / "bench")], capture_output=True, text=True, timeout=300)
    assert res.returncode != 0 and not (tmp_path / "bench").exists()
    assert res.stderr.strip().splitlines()[-1].endswith(
        "--trap-unaligned: powerpc cannot trap unaligned access (targets that can: cortex-m3, cortex-m4, cortex-m7)")
