"""Every command works for every bundle the exporter accepts (issue 42, items 3, 4 and 6): bundle shapes x commands.

Shapes: SN-S, SN-D, the irregular 24,9, the caps 256,256,256,256, and the committed format-1 example bundle; one
hidden unit ("1") is not a shape the exporter accepts, and is refused in one line. Commands: `fleetlab export
--check` (`--check-only` for the committed bundle), the host ctest of a build for the bundle (each shape built once
per session, into a tmp folder that `bench c` then reuses as its host build), and `fleetlab bench c --bundle
--target cortex-m4`.

Cost on two cores: the exports take about 25 s together, a host build about 30 s and a bench c (its M4 build, the
QEMU cost images, host timings) about 25 s per shape. By default the suite builds and benches 24,9 and SN-D (the
shapes of the issue), about 2.5 minutes for the file; FLEETLAB_HEAVY_TESTS=1 adds SN-S, 4 x 256 and the example
bundle (about 2.5 minutes more; SN-S and the example are built and benched by tests/test_firmware.py as well)."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import subprocess
from pathlib import Path

import pytest

from fleetlab.export.bundle import export_bundle
from fleetlab.export.f32_bound import recorded_tolerance
from fleetlab.models import save_model
from fleetlab.paths import repo_root

from required import need_tools
from small_models import quick_model

EXAMPLE = repo_root() / "firmware_c" / "bundles" / "example"
SHAPES = ["sn-s", "sn-d", "24,9", "256,256,256,256", "example"]
LIGHT = {"24,9", "sn-d"}  # built and benched by default (the shapes); the others with FLEETLAB_HEAVY_TESTS=1
HEAVY = os.environ.get("FLEETLAB_HEAVY_TESTS", "") not in ("", "0")


def _shapes(light: set[str]) -> list[str]:
    """The shapes a C test runs on: the light ones, every one with FLEETLAB_HEAVY_TESTS=1. The others are not
    collected (no skip): SN-S and the example bundle are built and tested by the rest of the suite already, and
    4 x 256 takes minutes per build on two cores."""
    return [s for s in SHAPES if s in light or HEAVY]


def _cli(*args: str) -> tuple[int, str, str]:
    """The real CLI entry point, in process (a subprocess per call would import torch again)."""
    from fleetlab.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as e:  # argparse refusing an option
            code = e.code
    return code, out.getvalue(), err.getvalue()


class Matrix:
    """Each shape's bundle (exported once through `fleetlab export --check`) and host build (built once)."""

    def __init__(self, root: Path):
        self.root = root
        self.exports: dict[str, tuple[Path, int, str, str]] = {}
        self.hosts: dict[str, Path] = {}

    def export(self, shape: str) -> tuple[Path, int, str, str]:
        if shape not in self.exports:
            if shape == "example":
                self.exports[shape] = (EXAMPLE, *_cli("export", "--check-only", str(EXAMPLE)))
            else:
                folder = self.root / shape.replace(",", "_")
                folder.mkdir()
                model = save_model(folder / "model.pt", quick_model(shape))
                bundle = folder / "bundle"
                self.exports[shape] = (bundle, *_cli("export", str(model), "--out", str(bundle), "--check",
                                                     "--builtin-vectors"))
        return self.exports[shape]

    def bundle(self, shape: str) -> Path:
        bundle, code, _, err = self.export(shape)
        assert code == 0, err
        return bundle

    def bench_dir(self, shape: str) -> Path:
        return self.root / shape.replace(",", "_") / "bench"

    def host(self, shape: str) -> Path:
        """The host build `bench c --build-dir bench_dir(shape)` uses as its own (the same configure options)."""
        if shape not in self.hosts:
            from fleetlab.host_tools.firmware.build import cmake_build

            need_tools("cmake", "gcc")
            self.hosts[shape] = cmake_build(self.bench_dir(shape) / "host", self.bundle(shape))
        return self.hosts[shape]


@pytest.fixture(scope="session")
def matrix(tmp_path_factory) -> Matrix:
    return Matrix(tmp_path_factory.mktemp("matrix"))


@pytest.mark.parametrize("shape", SHAPES)
def test_export_check(matrix, shape):
    bundle, code, out, err = matrix.export(shape)
    assert code == 0, err
    m = json.loads((bundle / "manifest.json").read_text())
    tol = recorded_tolerance(m)
    assert "bit for bit" in out and "ONNX: checker passed" in out
    assert f"tolerance {tol:.2e}" in out
    if shape != "example":
        assert m["arch"] == shape and m["float_tolerance"]["tolerance"] == tol
        assert m["onnx"]["max_scaled_diff_vs_torch"] <= tol
        assert m["model_image"]["format_version"] == (1 if shape == "sn-s" else 2)
        assert not [p for p in bundle.parent.iterdir() if ".partial-" in p.name]


def test_one_hidden_unit_is_refused_in_one_line(tmp_path):
    """"1" (one block of one unit: its LayerNorm output would be 0 for every input) is no architecture fleetlab
    trains or exports: `fleetlab fuse --arch 1` refuses it, and so does the exporter, given such a network by
    hand, before it writes anything."""
    from fleetlab.models.mlp import SlipNet

    code, _, err = _cli("fuse", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--arch", "1")
    assert code != 0 and "2 to 256 units are supported" in err
    with pytest.raises(ValueError, match="2 to 256 units are supported"):
        export_bundle(SlipNet((1,)), tmp_path / "b", inputs=quick_inputs())
    assert [p.name for p in tmp_path.iterdir()] == []


def quick_inputs():
    from fleetlab.export.vectors import draw_inputs

    return draw_inputs(1000, None, seed=3)


@pytest.mark.parametrize("shape", _shapes(LIGHT))
def test_host_ctest(matrix, shape):
    """Every host ctest passes for the shape: the vectors through the built-in model and through the bundle's
    model.img (fixed point bit-exact, float within the bundle's recorded tolerance), the C store tests with the
    image; a model beyond the build's image caps (4 x 256 units) has its image refused instead."""
    from fleetlab.host_tools.firmware.build import ctest

    out = ctest(matrix.host(shape))
    assert "100% tests passed" in out
    bundle = matrix.bundle(shape)
    n = json.loads((bundle / "manifest.json").read_text())["vectors"]["n"]
    assert re.search(rf"vectors={n} q_exact={n} f32_within_tol={n} ", out), out[-3000:]
    names = set(re.findall(r"Test +#\d+: (\w+) ", out))
    if shape == "256,256,256,256":
        assert "model_image_beyond_caps" in names and "vectors_host_model_image" not in names
        assert "test_store_table" not in names
    else:
        assert "vectors_host_model_image" in names
        assert ("test_store" if shape in ("sn-s", "example") else "test_store_table") in names
    if shape == "24,9":  # blocks of 24 and 9 units: no in-range h_bits breaks their centring bound
        assert "skipped: every block is 32 units or narrower" in out
    if shape == "sn-d":
        assert "h_bits 24 refused for block 0 (128 units)" in out


def test_big_endian_ctest_of_a_24_9_bundle(matrix):
    """The 24,9 bundle's C tests on the big-endian PowerPC under QEMU: every vector bit-exact through the
    built-in model, and through its model image where the target has the float path."""
    from fleetlab.host_tools.firmware import build, targets

    t = targets.get("powerpc")
    need_tools(*t.tools)
    bundle = matrix.bundle("24,9")
    out = build.ctest(build.cmake_build(matrix.root / "24_9" / "powerpc", bundle, target=t))
    assert "100% tests passed" in out, out[-3000:]
    n = json.loads((bundle / "manifest.json").read_text())["vectors"]["n"]
    assert re.search(rf"vectors={n} q_fail=0 f32_fail=0 extractor_fail=0 model=\w+ PASS", out), out[-3000:]


@pytest.mark.parametrize("shape", _shapes(LIGHT))
def test_bench_c(matrix, shape, capsys):
    """`fleetlab bench c --bundle X --target cortex-m4 --json` measures X: its own kernel, and its own model
    store and CANopen node (the node's image is X's model.img), or says why a figure is not measured."""
    from fleetlab.cli import bench_c
    from fleetlab.host_tools.firmware.bench import format_result
    from fleetlab.host_tools.firmware import targets

    need_tools("cmake", *targets.get("cortex-m4").tools)
    matrix.host(shape)  # the session's host build, reused
    parser = argparse.ArgumentParser()
    bench_c.add_arguments(parser)
    bundle = matrix.bundle(shape)
    args = parser.parse_args(["--bundle", str(bundle), "--build-dir", str(matrix.bench_dir(shape)),
                              "--target", "cortex-m4", "--iterations", "50", "--json"])
    assert bench_c.run(args) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["arch"] == json.loads((bundle / "manifest.json").read_text())["arch"]
    assert res["m4_instructions_per_inference_q"] > 0 and res["host_ns_per_inference_q"] > 0
    co = res["m4_canopen_node"]
    if shape == "256,256,256,256":
        for key in ("m4_canopen_node_ram_bytes", "m4_flash_bytes_model_slots", "m4_ram_bytes_model_slots"):
            assert res[key] is None, key
        assert set(res["m4_not_measured"]) == {"model_slots", "canopen_node"}
        assert "beyond this build's image caps" in res["m4_not_measured"]["canopen_node"]
        assert co == {"not_measured": res["m4_not_measured"]["canopen_node"]}
    else:
        assert res["m4_not_measured"] == {}
        assert res["m4_canopen_node_ram_bytes"] > 0 and res["m4_ram_bytes_model_slots"] > 0
        # the node was measured with this bundle's own image, not one left in the folder by another bundle
        assert co["image_bytes"] == (bundle / "model.img").stat().st_size
    text = format_result(res, "m4")
    assert ("not measured for this bundle" in text) == (shape == "256,256,256,256")


def test_bench_c_never_reports_another_bundles_images(tmp_path):
    """A cross build folder configured for an SN-S (store and CANopen images), then again for a bundle beyond the
    build's image caps: the folder's record now says it has neither image for this bundle, and why, so bench c
    reports those figures as not measured (before, it ran the images left in the folder by the SN-S and reported
    the SN-S node's figures as the new bundle's)."""
    from fleetlab.host_tools.firmware import targets
    from fleetlab.host_tools.firmware.build import configure_command, run
    from fleetlab.host_tools.firmware.measure import bundle_images

    need_tools("cmake", *targets.get("cortex-m4").tools)
    folder = tmp_path / "m4"
    t = targets.get("cortex-m4")
    run(configure_command(folder, EXAMPLE, target=t), what="cmake configure")
    assert bundle_images(folder)["canopen"] and bundle_images(folder)["store"]
    small = tmp_path / "small"
    export_bundle(quick_model("24,9"), small, inputs=quick_inputs())
    run(configure_command(folder, small, target=t, options={"SLIPEST_IMAGE_MAX_WEIGHTS": "100"}),
        what="cmake configure")
    images = bundle_images(folder)
    assert not images["canopen"] and not images["store"] and "SLIPEST_IMAGE_MAX_WEIGHTS=100" in images["why"]
    assert images["bundle"] == str(small.resolve())
