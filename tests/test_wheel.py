"""fleetlab without a clone (issue 26): the wheel carries the C source tree, an installed wheel runs the
whole flow from a temporary folder, and an integrator takes the C library out with `fleetlab c-sources`
into a plain CMake build.

The fresh venv is made outside the clone from this venv's interpreter, with no site packages of its own
beyond the wheel: a .pth line puts this venv's site-packages (torch, numpy, ... ) behind it, which makes
those modules importable but not the clone's editable fleetlab (its import hook lives in a .pth file of
that folder, and .pth files of a folder reached through a .pth line are not run). The test checks that
the fleetlab it runs is the wheel's.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fleetlab.c_sources import C_TREE
from fleetlab.export.vectors import read_vectors
from fleetlab.paths import repo_root

REPO = repo_root()


def _sh(cmd: list, *, cwd: Path, env: dict | None = None, timeout: float = 900) -> str:
    res = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))} exited {res.returncode}:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res.stdout + res.stderr


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    _sh([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "--no-build-isolation", "-q", "-w", out],
        cwd=out)
    (whl,) = out.glob("fleetlab-*.whl")
    return whl


def test_wheel_carries_the_c_tree(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for must in ("CMakeLists.txt", "firmware_c/src/slipest_infer_q.c", "firmware_c/include/slipest_node.h",
                 "firmware_c/cmake/cortex-m4.cmake", "firmware_c/cmake/generate_dbc.cmake", "dbc/slipest.dbc",
                 "canopen_od/generate.py", "firmware_c/bundles/example/model.img", "firmware_c/fuzz/fuzz_store.c",
                 "firmware_c/eva/eva_driver.c", "export/c/check_vectors.c"):
        assert f"fleetlab/c_tree/{must}" in names, must
    assert "fleetlab/dbc/slipest.dbc" in names and "fleetlab/errors.py" in names
    assert not any(re.search(r"\.(o|a|so|pyc|dump|ctu-info)$", n) for n in names)


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> dict:
    """A new venv outside the clone with only the wheel installed; returns the environment to run it in."""
    root = tmp_path_factory.mktemp("fresh")
    venv_dir = root / "venv"
    venv.EnvBuilder(with_pip=False).create(venv_dir)
    vpy = venv_dir / "bin" / "python"
    site = Path(_sh([vpy, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=root).strip())
    (site / "zz_clone_venv_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _sh([sys.executable, "-m", "pip", "--python", vpy, "install", "--no-deps", "--no-index", "-q", wheel], cwd=root)
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "FLEETLAB_BUILD_ROOT")}
    env.update(PATH=f"{venv_dir / 'bin'}{os.pathsep}{env['PATH']}", XDG_CACHE_HOME=str(root / "cache"),
               HOME=str(root / "home"))
    work = root / "work"
    work.mkdir()
    return {"env": env, "work": work, "venv": venv_dir, "cache": root / "cache"}


def _fleetlab(installed: dict, *args, timeout: float = 900) -> str:
    return _sh([installed["venv"] / "bin" / "fleetlab", *args], cwd=installed["work"], env=installed["env"],
               timeout=timeout)


def test_installed_fleetlab_is_the_wheel_not_the_clone(installed):
    out = _sh([installed["venv"] / "bin" / "python", "-c",
               "import fleetlab, fleetlab.paths as p; print(fleetlab.__file__); print(p.repo_root(), p.in_clone())"],
              cwd=installed["work"], env=installed["env"])
    file, tree = out.splitlines()[:2]
    assert file.startswith(str(installed["venv"])), file
    assert tree.startswith(str(installed["venv"])) and tree.endswith("c_tree False"), tree
    assert "usage: fleetlab bench c" in _fleetlab(installed, "bench", "c", "--help")


def test_the_whole_flow_runs_from_the_wheel(installed):
    """simulate, fuse (short budget), export --check, emulate --link slcan (bit-exact), bench c on the host,
    upload --emulate --activate: each from a temporary folder, building C in the user's cache folder."""
    work = installed["work"]
    _fleetlab(installed, "simulate", "--out", "sim", "--seed", "1", "--scale", "0.1")
    _fleetlab(installed, "fuse", "--data", "sim", "--out", "fused", "--cal-size", "60", "--epochs", "2",
              "--generations", "4", "--ants", "30", "--no-progress")
    out = _fleetlab(installed, "export", "fused/fused.pt", "--out", "bundle", "--check")
    assert "bit for bit" in out
    _fleetlab(installed, "emulate", "--bundle", "bundle", "--source", "sim", "--link", "slcan",
              "--max-windows", "20", "--json", "emulate.json", "--no-progress")
    report = json.loads((work / "emulate.json").read_text())
    assert report["windows"] == 20 and report["bit_exact"] == 20 and report["mismatches"] == 0, report
    bench = json.loads(_fleetlab(installed, "bench", "c", "--bundle", "bundle", "--iterations", "50", "--json"))
    assert bench["host_ns_per_inference_q"] > 0
    up = json.loads(_fleetlab(installed, "upload", "--bundle", "bundle", "--emulate", "--activate", "--json"))
    assert up["activated"], up
    builds = list(installed["cache"].glob("fleetlab/build-*/"))
    assert builds and (builds[0] / "emulate").is_dir(), "C builds go to the user's cache folder"
    assert not (work / "build").exists()


INTEGRATOR_MAIN = r"""
#include <stdio.h>
#include <stdlib.h>
#include "slipest_bundle.h"
#include "slipest_infer.h"
#include "slipest_vectors.h"

int main(int argc, char **argv)
{
    static uint8_t buf[1 << 20];
    FILE *f = (argc == 2) ? fopen(argv[1], "rb") : NULL;
    if (f == NULL) { fprintf(stderr, "usage: check_bundle vectors.bin\n"); return 2; }
    size_t len = fread(buf, 1, sizeof buf, f);
    fclose(f);
    slipest_vectors_t v;
    const char *why = "";
    if (slipest_vectors_parse(buf, len, &v, &why) != 0) { fprintf(stderr, "bad vectors: %s\n", why); return 2; }
    uint32_t exact = 0;
    for (uint32_t i = 0; i < v.n; i++) {
        int16_t q[12];
        int32_t want[3], got[3];
        slipest_vectors_q_input(&v, i, q);
        slipest_vectors_q_logits(&v, i, want);
        (void)slipest_infer_q(slipest_bundle_model_q(), q, got, NULL);
        exact += (got[0] == want[0] && got[1] == want[1] && got[2] == want[2]) ? 1u : 0u;
    }
    printf("bit-exact %u of %u\n", (unsigned)exact, (unsigned)v.n);
    return exact == v.n ? 0 : 1;
}
"""


def test_integrator_builds_the_library_with_plain_cmake(tmp_path):
    """`fleetlab c-sources --out DIR`, then a firmware-like CMake project that add_subdirectory()s DIR and
    checks every vector of the example bundle bit for bit through the public API."""
    lib = tmp_path / "slipest"
    out = _sh([sys.executable, "-m", "fleetlab.cli", "c-sources", "--out", lib], cwd=tmp_path)
    assert "add_subdirectory" in out
    assert all((lib / entry).exists() for entry in C_TREE)
    app = tmp_path / "app"
    app.mkdir()
    (app / "main.c").write_text(INTEGRATOR_MAIN)
    (app / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\nproject(rover_firmware C)\n"
        f'add_subdirectory("{lib}" slipest EXCLUDE_FROM_ALL)\n'
        "add_executable(check_bundle main.c)\ntarget_link_libraries(check_bundle PRIVATE slipest slipest_vectors)\n")
    build = tmp_path / "build"
    _sh(["cmake", "-S", app, "-B", build, f"-DPython3_EXECUTABLE={sys.executable}"], cwd=tmp_path)
    _sh(["cmake", "--build", build, "-j2", "--target", "check_bundle"], cwd=tmp_path)
    bundle = lib / "firmware_c" / "bundles" / "example"
    n = len(read_vectors(bundle))
    res = _sh([build / "check_bundle", bundle / "vectors.bin"], cwd=tmp_path)
    assert f"bit-exact {n} of {n}" in res and n >= 1000
    assert not any((build / "slipest").glob("test_*")), "EXCLUDE_FROM_ALL: only what the firmware links is built"
