"""The constants C and Python share come from one source each, and both sides agree (issue 27): a C
program built against the real headers (slipest_status.h, the generated slipest_co_od.h and
slipest_image_layout.h, slipest_store.h, slipest_node.h) prints what the compiler sees, and the
Python modules that name the same facts are compared with it."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from fleetlab.assurance.sources import generate_dbc, include_dirs
from fleetlab.canopen_od import objects as od
from fleetlab.export import image_layout
from fleetlab.host_tools.binding import CCounters
from fleetlab.host_tools.canopen_node import nvm_sectors, store_image_max
from fleetlab.host_tools.emulator import HOST_LIBRARY_TARGET, build, find_artifact
from fleetlab.host_tools.status_codes import status


@pytest.fixture(scope="module")
def c_side(tmp_path_factory) -> dict[str, int]:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.fail("no C compiler on PATH: scripts/setup.sh installs build-essential (scripts/apt-packages.txt)")
    tmp = tmp_path_factory.mktemp("constants")
    gen = generate_dbc(tmp / "generated").parent
    lines = ['#include <stddef.h>', '#include <stdio.h>', '#include "slipest_co.h"', '#include "slipest_node.h"',
             '#include "slipest_store.h"', "#define P(name, v) printf(\"%s %ld\\n\", name, (long)(v))",
             "int main(void) {"]
    lines += [f'P("{n}", {n});' for n in status()]
    lines += [f'P("ABORT_{n}", SLIPEST_CO_ABORT_{n});' for n, _, _ in od.ABORT_CODES]
    lines += [f'P("EMCY_{n}", SLIPEST_CO_EMCY_{n});' for n, _, _ in od.EMCY_CODES]
    lines += [f'P("CNT_{n}", offsetof(slipest_counters_t, {n}));' for n in od.ESTIMATOR_COUNTERS]
    lines += ['P("N_COUNTERS", sizeof(slipest_counters_t) / sizeof(uint32_t));',
              'P("N_STORE_COUNTERS", sizeof(slipest_store_counters_t) / sizeof(uint32_t));',
              'P("IMAGE_MAX", SLIPEST_IMAGE_MAX_SIZE);', 'P("STORE_IMAGE_MAX", SLIPEST_STORE_IMAGE_MAX);', 'P("NVM_SECTORS_256", SLIPEST_STORE_NVM_SECTORS(256u));',
              'P("NVM_SECTORS_64", SLIPEST_STORE_NVM_SECTORS(64u));', "return 0; }"]
    src = tmp / "constants.c"
    src.write_text("\n".join(lines) + "\n")
    exe = tmp / "constants"
    # as CMake builds the example (SN-S) bundle's library: without the layer-table reader
    subprocess.run([cc, "-std=c99", "-DSLIPEST_LAYER_TABLE=0", *[f"-I{d}" for d in include_dirs(None, gen)], str(src),
                    "-o", str(exe)],
                   check=True, capture_output=True, text=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    return {k: int(v) for k, v in (line.split() for line in out.splitlines())}


def test_status_codes_are_the_headers(c_side) -> None:
    assert status() == {k: v for k, v in c_side.items() if k.startswith("SLIPEST_")}
    assert status()["SLIPEST_E_NVM"] == -14  # the parse reads values, not positions


def test_abort_and_emcy_codes_agree(c_side) -> None:
    def c_codes(prefix: str) -> dict[str, int]:
        return {k: v for k, v in c_side.items() if k.startswith(prefix)}

    assert {f"ABORT_{n}": c for n, c, _ in od.ABORT_CODES} == c_codes("ABORT_")
    assert {f"EMCY_{n}": c for n, c, _ in od.EMCY_CODES} == c_codes("EMCY_")


def test_counter_names_and_order_agree(c_side) -> None:
    """slipest_counters_t holds exactly the estimator counters, in ESTIMATOR_COUNTERS' order, which is the
    binding's and the first sub-indices of 0x2003; every store counter is a field (the build checks the
    names through offsetof), and there are no others."""
    assert [c_side[f"CNT_{n}"] for n in od.ESTIMATOR_COUNTERS] == [4 * i for i in range(len(od.ESTIMATOR_COUNTERS))]
    assert c_side["N_COUNTERS"] == len(od.ESTIMATOR_COUNTERS)
    assert [name for name, _ in CCounters._fields_] == list(od.ESTIMATOR_COUNTERS)
    assert od.COUNTERS[:len(od.ESTIMATOR_COUNTERS)] == od.ESTIMATOR_COUNTERS
    assert c_side["N_STORE_COUNTERS"] == len(od.STORE_COUNTERS)


def test_image_sizes_agree(c_side) -> None:
    assert c_side["IMAGE_MAX"] == image_layout.CURRENT.max_size


def test_nvm_sectors_are_read_from_the_library(c_side) -> None:
    """Python sizes an NVM through the library's slipest_store_nvm_sectors() (no second copy of
    SLIPEST_STORE_NVM_SECTORS); it agrees with the macro the compiler sees, and a sector size the store
    refuses is a clear error."""
    lib = find_artifact(build(None, targets=(HOST_LIBRARY_TARGET,)), "libslipest_host.so")
    assert c_side["NVM_SECTORS_256"] == nvm_sectors(lib, 256) and c_side["NVM_SECTORS_64"] == nvm_sectors(lib, 64)
    with pytest.raises(ValueError, match="does not accept"):
        nvm_sectors(lib, 32)


def test_store_image_max_follows_the_build(c_side) -> None:
    """The store's largest image (SLIPEST_STORE_IMAGE_MAX), read through the library: an SN-S-only build keeps
    the format-1 maximum; a build with the layer-table reader takes an SN-D image with its float model and tag,
    and its NVM size follows (two record sectors, two slots of that many bytes)."""
    lib = find_artifact(build(None, targets=(HOST_LIBRARY_TARGET,)), "libslipest_host.so")
    assert store_image_max(lib) == c_side["STORE_IMAGE_MAX"] == image_layout.CURRENT.max_size
    table_lib = find_artifact(build(None, targets=(HOST_LIBRARY_TARGET,), options={"SLIPEST_LAYER_TABLE": "ON"}),
                              "libslipest_host.so")
    big = store_image_max(table_lib)
    assert big >= image_layout.V2.image_size((128, 64, 32)) > image_layout.CURRENT.max_size
    for sector in (64, 256):
        assert nvm_sectors(table_lib, sector) == 2 + 2 * (-(-big // sector))
