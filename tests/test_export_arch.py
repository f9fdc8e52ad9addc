"""Every architecture reaches C (issue 28): export of SN-D, an irregular shape and a model at the caps
writes the whole bundle, the bundle reads back, and the C kernels (one layer-table kernel, its float
twin) reproduce its vectors bit for bit under ASan/UBSan; agreement with float on real data."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from fleetlab.export import intref
from fleetlab.export.bundle import check_bundle, export_bundle, load_bundle
from fleetlab.export.quant import QNet
from fleetlab.export.vectors import draw_inputs
from fleetlab.models import build
from fleetlab.models.train import train_classifier

from c_check import INCLUDE, build_check, check_argv
from planted import LAYER_E_CLAMP, LAYER_E_UNCLAMPED, planted_src
from required import need_tool as need
from required import need_tools
from small_models import quick_model

ARCHS = ["sn-d", "24,9", "256,256,256,256"]
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module", params=ARCHS)
def arch_bundle(request, tmp_path_factory):
    out = tmp_path_factory.mktemp("arch") / "bundle"
    export_bundle(quick_model(request.param), out, inputs=draw_inputs(1000, None, seed=3))
    return request.param, out


def test_bundle_is_complete_and_reads_back(arch_bundle):
    arch, out = arch_bundle
    m = json.loads((out / "manifest.json").read_text())
    assert m["arch"] == arch and m["headers"]["layer_table"]
    assert m["model_image"]["format_version"] == 2 and m["model_image"]["arch_id"] == 2  # the layer table
    for name in ("model.onnx", "slipest_model_q.h", "slipest_model_f32.h", "model.img", "vectors.npz", "vectors.bin"):
        assert name in m["files"]
    b = load_bundle(out)
    assert isinstance(b.qparams, QNet) and ",".join(map(str, b.qparams.hidden)) in (arch, "128,64,32")
    assert [blk["width"] for blk in m["quantization"]["blocks"]] == list(b.qparams.hidden)
    lines = check_bundle(out)
    assert any("bit for bit" in line for line in lines)


def test_edited_layer_table_header_is_refused(arch_bundle, tmp_path):
    import shutil

    arch, out = arch_bundle
    copy = tmp_path / "b"
    shutil.copytree(out, copy)
    q = copy / "slipest_model_q.h"
    text = q.read_text()
    q.write_text(re.sub(r"\.fy = (\d+)", lambda mm: f".fy = {int(mm[1]) - 1}", text, count=1))
    with pytest.raises(ValueError):
        load_bundle(copy)


def test_c_kernels_match_the_vectors_sanitized(arch_bundle, tmp_path):
    """The layer-table kernel and the float path on the bundle's vectors (edge rows at the int16 rails
    included), gcc with ASan + UBSan: every logit and saturation count equal, floats within the bundle's float
    tolerance."""
    _sanitized_check(arch_bundle[1], tmp_path)


def test_irregular_shape_c_kernels_sanitized(irregular_bundle, tmp_path):
    """IRREGULAR, the shape every QEMU target runs too (test_bit_exact_under_qemu), on the host the same way."""
    _sanitized_check(irregular_bundle, tmp_path)


def _sanitized_check(out: Path, tmp_path: Path) -> None:
    exe = build_check(out, tmp_path, need("gcc"), ["-fsanitize=undefined,address", "-fno-sanitize-recover=all"])
    res = subprocess.run(check_argv(exe, out), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert re.search(r"q mismatches 0 .*f32 > tol 0", res.stdout)


@pytest.mark.parametrize("arch_bundle", ["24,9"], indirect=True)
def test_fuzzers_run_clean_on_a_layer_table_image(arch_bundle, tmp_path):
    """libFuzzer (ASan + UBSan) on the format-2 path: fuzz_image_table mutates the bundle's image through
    the layer-table reader into both kernels at the int16 rails, fuzz_store drives the store (uploads,
    activation, power cuts) from that image. A small shape, so that most mutations land in the table,
    the shifts and the bounds rather than in weights; SN-D runs the same reader and kernel."""
    _, bundle = arch_bundle
    need("clang")
    env = {**os.environ, "FUZZ_BUNDLE": str(bundle), "FUZZ_TARGETS": "fuzz_image_table fuzz_store"}
    proc = subprocess.run([str(REPO / "scripts" / "fuzz.sh"), "6", str(tmp_path / "fuzz")], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-4000:]
    execs = dict(re.findall(r"^(fuzz_\w+) executions=(\d+)", proc.stdout, flags=re.M))
    assert set(execs) == {"fuzz_image_table", "fuzz_store"} and all(int(v) > 1000 for v in execs.values()), execs
    seed = tmp_path / "fuzz" / "corpus" / "fuzz_image_table" / "seed.img"
    assert seed.read_bytes() == (bundle / "model.img").read_bytes()


def test_a_build_below_the_model_is_refused(arch_bundle, tmp_path):
    """Caps lowered below the model's widest block stop the build (no kernel runs out of scratch)."""
    _, out = arch_bundle
    src = tmp_path / "one.c"
    src.write_text('#include "slipest_model_q.h"\nint main(void) { return SLIPEST_MODEL_Q_INCLUDED.n_layers == 0; }\n')
    res = subprocess.run([need("gcc"), "-std=c99", f"-I{INCLUDE}", f"-I{out}", "-DSLIPEST_MAX_WIDTH=8",
                          "-fsyntax-only", str(src)], capture_output=True, text=True)
    assert res.returncode != 0 and "width_check" in res.stderr


def test_sn_s_still_exports_the_unrolled_layout_and_an_image(tmp_path):
    out = tmp_path / "b"
    export_bundle(quick_model("sn-s"), out, inputs=draw_inputs(1000, None, seed=3))
    m = json.loads((out / "manifest.json").read_text())
    assert "layer_table" not in m["headers"] and (out / "model.img").exists()
    assert ".layers" not in (out / "slipest_model_q.h").read_text()


@pytest.mark.parametrize("arch", ["sn-s", "sn-d"])
def test_fixed_point_agrees_with_float_on_real_data(arch, real_data_dir, tmp_path):
    """A model trained on the Fleet-To-Lab files, exported with --data: at least 99.5 % of the bundle's
    vectors (drawn from those windows) and of all windows get the float model's class."""
    from fleetlab.data.dataset import load_dataset

    ds = load_dataset(real_data_dir)
    x = np.concatenate([ds.xy(r)[0] for r in ds.roles])
    y = np.concatenate([ds.xy(r)[1] for r in ds.roles])
    torch.set_num_threads(1)
    model = train_classifier(build(arch, seed=0), x, y, epochs=4, seed=0)
    b = export_bundle(model, tmp_path / "b", inputs=draw_inputs(1200, x, seed=0), data_dirs=[real_data_dir])
    assert b.manifest["vectors"]["class_agreement"] >= 0.995
    rep = json.loads((tmp_path / "b" / "accuracy.json").read_text())
    assert rep["datasets"][0]["all"]["agreement"] >= 0.995
    assert intref.run(b.qparams, np.zeros((1, 12), np.int16))[1].tolist() == [0]


# --- Frama-C EVA on the layer-table kernel -----------------------------------------------------

@pytest.fixture(scope="module")
def caps_bundle(tmp_path_factory):
    """A model at the build's caps: SLIPEST_MAX_LAYERS blocks of SLIPEST_MAX_WIDTH units (4 x 256)."""
    out = tmp_path_factory.mktemp("eva_caps") / "bundle"
    export_bundle(quick_model("256,256,256,256"), out, inputs=draw_inputs(200, None, seed=3))
    return out


# At the caps EVA joins the rows and units of a block (256 of them); precision 3 unrolls the short loops
# (bit lengths, the block loop) and proves the kernel in about 30 s; the default precision 5 takes minutes
# (scripts/eva_at_caps.py, opt-in, docs/assurance.md).
CAPS_PRECISION = ["-eva-precision", "3"]


@pytest.fixture(scope="module")
def caps_eva(caps_bundle, snd_bundle, tmp_path_factory):
    """EVA at the caps on the kernel as it is and without the clamp of e (LAYER_E_CLAMP), and on SN-D (blocks
    of 128, 64 and 32 units), the Frama-C runs side by side (single-threaded processes of about 35, 35 and 20 s)."""
    need("frama-c")
    from fleetlab.assurance import analysers
    from fleetlab.assurance.sources import concurrently

    src = planted_src(tmp_path_factory.mktemp("unclamped"), "slipest_infer_table_q.c", LAYER_E_CLAMP, LAYER_E_UNCLAMPED)
    options = analysers.EVA_OPTIONS + CAPS_PRECISION
    (clean,), (planted,), (snd,) = concurrently([
        lambda: analysers.frama_c_eva(caps_bundle, entries=["eva_infer_q"], options=options),
        lambda: analysers.frama_c_eva(caps_bundle, entries=["eva_infer_q"], src_dir=src, options=options),
        lambda: analysers.frama_c_eva(snd_bundle, entries=["eva_infer_q"], options=options)])
    return clean, planted, snd


def test_frama_c_eva_layer_kernel_at_the_caps(caps_eva):
    """EVA at the caps (4 blocks of 256 units): no alarm for every int16 input, although the analysis joins
    the rows and units of each block (the clamps the proof states where they are used, docs/fixed_point.md)."""
    res = caps_eva[0]
    assert "Frama_C_show_each_class: {0; 1; 2}" in res.log  # the analysis ran through the whole kernel
    assert res.alarms == [], "\n".join(res.alarms)


def test_frama_c_eva_layer_kernel_with_blocks_of_different_widths(caps_eva):
    """EVA on SN-D, whose blocks are narrower than the scratch (128, 64, 32 of 256 units): no alarm. The unit
    loops stop at `p < end`; with `p != end` EVA widened p past a narrow block's end to the scratch's and
    reported 7 out-of-bounds and uninitialised reads (`fleetlab assure` failed on every SN-D bundle)."""
    res = caps_eva[2]
    assert "Frama_C_show_each_class: {0; 1; 2}" in res.log
    assert res.alarms == [], "\n".join(res.alarms)


def test_frama_c_eva_finds_a_removed_saturation_in_the_layer_kernel(caps_eva):
    """At the caps, without the clamp that states |e| <= 2^14 (a bound that holds only through e's relation
    to max|d|), EVA reports the possible overflow of e * e in centre_pass: the zero above is not vacuous."""
    res = caps_eva[1]
    assert any("e_ * e_" in a for a in res.alarms), "\n".join(res.alarms)


# --- the SN-D bundle served by the emulator, and on CPU targets under QEMU ------------------------

@pytest.fixture(scope="module")
def snd_bundle(tmp_path_factory):
    out = tmp_path_factory.mktemp("snd") / "bundle"
    export_bundle(quick_model("sn-d"), out, inputs=draw_inputs(1000, None, seed=3))
    return out


def test_misra_record_covers_a_layer_table_bundle(snd_bundle):
    """`fleetlab assure misra` on an SN-D bundle: its generated headers (two compile-time checks each, the
    layer table's width too) are within the record, whose bundle rows count exactly what they have. Only the two
    sources that include the headers are analysed (the library's own counts are the example bundle's test: in
    a part of the library, macros the rest uses look unused)."""
    from fleetlab.assurance import misra

    src = REPO / "firmware_c" / "src"
    found, _, _ = misra.run_cppcheck(snd_bundle, sources=[src / "slipest_bundle_q.c", src / "slipest_bundle_f32.c"])
    res = misra.compare(found)
    assert not [u for u in res.unrecorded if u[1].startswith(misra.BUNDLE_FILES)], res.unrecorded
    in_headers = {k: n for k, n in res.findings.items() if k[1].startswith(misra.BUNDLE_FILES)}
    assert in_headers[("2.3", "bundle/slipest_model_q.h")] == in_headers[("2.3", "bundle/slipest_model_f32.h")] == 2
    assert in_headers == {k: n for k, n in res.recorded.items() if k[1].startswith(misra.BUNDLE_FILES)}


def test_a_build_folder_follows_its_bundle_to_the_layer_table_and_back(snd_bundle, tmp_path):
    """CMake's SLIPEST_LAYER_TABLE (AUTO by default) compiles the layer-table kernels when the bundle needs them,
    also when one build folder is configured again with another bundle (`fleetlab assure` on an SN-S bundle,
    then on an SN-D one, refused the second: the folder's cache kept the first bundle's OFF); ON stays ON, and
    OFF with a layer-table bundle is refused in one line."""
    example = REPO / "firmware_c" / "bundles" / "example"

    def configure(folder: str, bundle: Path, *options: str) -> str:
        proc = subprocess.run(["cmake", "-S", str(REPO), "-B", str(tmp_path / folder), f"-DSLIPEST_BUNDLE={bundle}",
                               *options], capture_output=True, text=True, timeout=300)
        if proc.returncode:
            return proc.stderr
        return re.search(r"-- slipest: layer-table kernels (\w+) ", proc.stdout)[1]

    assert [configure("a", b) for b in (example, snd_bundle, example)] == ["OFF", "ON", "OFF"]
    by_hand = [configure("b", example, "-DSLIPEST_LAYER_TABLE=ON"), configure("b", snd_bundle), configure("b", example)]
    assert by_hand == ["ON", "ON", "ON"]
    refused = " ".join(configure("c", snd_bundle, "-DSLIPEST_LAYER_TABLE=OFF").split())  # CMake wraps its lines
    assert "is a layer-table model; SLIPEST_LAYER_TABLE cannot be OFF" in refused, refused


def test_emulator_serves_an_sn_d_bundle_bit_exact_over_slcan(snd_bundle):
    """`fleetlab emulate --bundle SN-D --link slcan`: the emulator process built with the bundle's
    layer-table headers, simulated telemetry over a real pty, every window bit-exact with intref."""
    from fleetlab.host_tools.emulate import DEFAULT_SCALE, emulate
    from fleetlab.host_tools.emulator import build
    from fleetlab.host_tools.sources import sim_source

    build(snd_bundle)
    sim = sim_source(seed=0, scale=DEFAULT_SCALE)
    s = emulate(snd_bundle, sim, "slcan", progress=False).summary()
    assert s["windows"] == sim.n_windows and s["bit_exact"] == s["windows"], s["first_problems"]
    assert s["mismatches"] == 0 and s["unexplained_windows"] == 0


def test_emulator_reads_an_sn_d_model_image_bit_exact(snd_bundle, tmp_path):
    """The C format-2 reader (slipest_image_table.c): the emulator loads the SN-D model.img at run time and
    is bit-exact on every vector (fixed point) and within the bundle's float tolerance; a flipped byte and a layer
    table that disagrees with the payload are refused with their statuses."""
    from fleetlab.export import image_layout
    from fleetlab.host_tools.emulator import EMULATOR_TARGET, build, find_artifact

    emu = find_artifact(build(snd_bundle), EMULATOR_TARGET)
    img = (snd_bundle / "model.img").read_bytes()
    res = subprocess.run([str(emu), "--model", str(snd_bundle / "model.img"), "--vectors",
                          str(snd_bundle / "vectors.bin")], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and re.search(r"vectors=(\d+) q_exact=\1 f32_within_tol=\1 .*PASS", res.stdout), \
        res.stdout + res.stderr
    V2 = image_layout.V2
    width_at = V2.table_at + V2.record_offsets["width"]
    flipped = img[:500] + bytes([img[500] ^ 1]) + img[501:]
    wider = bytearray(img)
    wider[width_at] += 1
    for name, data, status in (("crc", flipped, "CRC mismatch"),
                               ("table", image_layout.reseal(bytes(wider)), "wrong length")):
        (tmp_path / f"{name}.img").write_bytes(data)
        res = subprocess.run([str(emu), "--model", str(tmp_path / f"{name}.img"), "--vectors",
                              str(snd_bundle / "vectors.bin")], capture_output=True, text=True, timeout=300)
        assert res.returncode == 2 and f"model image rejected: {status}" in res.stderr, (name, res.stderr)


def _runnable_targets() -> list[str]:
    from fleetlab.host_tools.firmware import targets

    return [name for name, t in targets.discover().items() if t.runs]


@pytest.fixture(scope="module")
def irregular_bundle(tmp_path_factory):
    """IRREGULAR with a few units whose LayerNorm output leaves int16 on some inputs (gamma ~ 2, beta ~ +-7.3):
    the saturation count of every vector is compared too (the DSP cores count from the Q flag and recount)."""
    from fleetlab.export import bundle as bundle_mod

    quantize = bundle_mod.quantize

    def saturating(fn, *args, **kwargs):
        qn = quantize(fn, *args, **kwargs)
        for blk, sign, n in zip(qn.blocks, (1, -1), (3, 2)):
            blk.g[:n] = 32767
            blk.bb[:n] = sign * (30000 << (blk.fy - 12))
        return qn

    out = tmp_path_factory.mktemp("irr") / "bundle"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(bundle_mod, "quantize", saturating)
        export_bundle(quick_model(IRREGULAR), out, inputs=draw_inputs(1000, None, seed=3))
    sats = np.load(out / "vectors.npz")["q_saturations"]
    assert sats.sum() > 1000
    return out


# SN-D and an irregular shape on every target with an emulator. The irregular shape
# takes the paths of the M4's kernel that SN-D does not: a block of 20 inputs (the four-row product loop
# entered at its last quarter), one of 24 inputs and 11 rows (row pairs entered at an eighth, an odd last
# row), one of 11 inputs (rows one by one), an odd width (the C centring loop, the hidden loop entered at its
# second unit) and widths of 2 mod 4 (centring entered at its second pair, a pair of the shifted sum left over)
IRREGULAR = "20,24,11,10"
# The M4's written-out product loops are entered part-way through their first pass: the row pairs (a multiple
# of 8 inputs) at (n_in / 8) mod 8 eighths, the four-row groups (n_in = 4 mod 8, not the 12 features) at
# (n_in / 4) mod 4 quarters. SN-D (128, 64 inputs) and IRREGULAR (20, 24) take eighths 0 and 3 and quarter 1;
# these shapes' hidden blocks take the others (see test_the_m4_cases_enter_every_product_loop_entry).
ENTRY_SHAPES = ["40,48,28,8", "8,16,56,32", "32,9"]
CASES = ([(arch, name) for arch in ("sn-d", IRREGULAR) for name in _runnable_targets()]
         + [(shape, "cortex-m4") for shape in ENTRY_SHAPES])


def _block_inputs(arch: str) -> list[int]:
    """The input counts of the hidden blocks after the first (the first block's 12 features have their own loop)."""
    widths = [128, 64, 32] if arch == "sn-d" else [int(w) for w in arch.split(",")]
    return widths[:-1]


def test_the_m4_cases_enter_every_product_loop_entry():
    m4 = [arch for arch, name in CASES if name == "cortex-m4"]
    eighths = {(n // 8) % 8 for arch in m4 for n in _block_inputs(arch) if n % 8 == 0}
    quarters = {(n // 4) % 4 for arch in m4 for n in _block_inputs(arch) if n % 8 == 4 and n != 12}
    assert eighths == set(range(8)) and quarters == {1, 3}  # n = 4 mod 8 leaves an odd n / 4: quarters 1, 3


@pytest.mark.parametrize("arch,name", CASES)
def test_bit_exact_under_qemu(snd_bundle, irregular_bundle, tmp_path, arch, name):
    from fleetlab.host_tools.firmware import build, targets

    if arch == "sn-d":
        bundle = snd_bundle
    elif arch == IRREGULAR:
        bundle = irregular_bundle
    else:
        bundle = tmp_path / "bundle"
        export_bundle(quick_model(arch), bundle, inputs=draw_inputs(300, None, seed=5))
    t = targets.get(name)
    need_tools(*t.tools)  # skips outside CI, fails under FLEETLAB_REQUIRE_TOOLS, naming the package
    out = build.ctest(build.cmake_build(tmp_path / name, bundle, target=t))
    assert "100% tests passed" in out
    passes = re.findall(r"vectors=\d+ q_fail=0 f32_fail=0 extractor_fail=0 model=\w+ PASS", out)
    assert len(passes) == (1 if t.integer_only else 2), out[-3000:]
    for what in ("slipest_test_q.elf", "libslipest_q.a"):
        assert f"{what}: 0 soft-float helper symbols (expected absent)" in out


def test_m4_built_for_firmware_that_traps_unaligned_access(irregular_bundle, tmp_path):
    """-DSLIPEST_TRAP_UNALIGNED=ON (firmware that sets SCB->CCR.UNALIGN_TRP): the test images set the trap at
    reset, and every image runs with it, the estimator bit-exact on every vector; the hidden loop is the
    portable one (the written-out loop's SMLSD is absent). The control: the same build with the kernel
    compiled for unaligned access again (-munaligned-access after the option's -mno-unaligned-access) takes
    the written-out loop, whose GELU word read is unaligned, and QEMU raises the UsageFault, so the trap is
    real and the first build's pass means something."""
    from fleetlab.host_tools.firmware import build, targets

    t = targets.get("cortex-m4")
    need_tools(*t.tools, "arm-none-eabi-objdump")

    def smlsd_count(build_dir: Path) -> int:
        dis = subprocess.run(["arm-none-eabi-objdump", "-d", str(build_dir / "libslipest_q.a")],
                             capture_output=True, text=True, check=True).stdout
        return len(re.findall(r"\tsmlsd\t", dis))

    trap = build.cmake_build(tmp_path / "trap", irregular_bundle, target=t, options={"SLIPEST_TRAP_UNALIGNED": "ON"})
    out = build.ctest(trap)
    assert "100% tests passed" in out
    assert len(re.findall(r"vectors=\d+ q_fail=0 f32_fail=0 extractor_fail=0 model=\w+ PASS", out)) == 2, out[-3000:]
    assert smlsd_count(trap) == 0

    control = build.cmake_build(tmp_path / "control", irregular_bundle, target=t,
                                options={"SLIPEST_TRAP_UNALIGNED": "ON", "SLIPEST_TARGET_KERNEL_OPT": "-munaligned-access"})
    assert smlsd_count(control) > 0
    proc = subprocess.run(build.ctest_command(control, "^vectors_q_"), capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "FAULT" in proc.stdout, proc.stdout[-2000:]
