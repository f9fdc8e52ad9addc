"""Shared pytest fixtures, and the hooks that order the files and give each xdist worker its build root."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_REAL_DATA = REPO_ROOT.parent / "shared" / "data" / "fleet_to_lab"
HOW_TO_SUPPLY = ("download the original Fleet-To-Lab CSV files (MIT licence; see docs/real_data.md) into one folder "
                 "and set FLEETLAB_REAL_DATA=/that/folder")


# The longest test files (minutes each: cross builds for every CPU, Frama-C, the demo, fuzzing), started first so
# that under pytest-xdist the short files fill the workers' ends instead of one long file running alone at the end.
# Only an order: a file missing here runs after these, in collection order.
LONG_FIRST = ("test_export_arch.py", "test_firmware.py", "test_demo.py", "test_assurance.py", "test_other_cpus.py",
              "test_cluster.py", "test_targets.py", "test_bundle_matrix.py", "test_wheel.py", "test_model_slots.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FIRST)))  # stable: a file's tests keep their order


def pytest_configure(config):
    """Under pytest-xdist (scripts/test.sh) each worker process gets its own build root, unless one was given: the
    default build/ folders (bench, assure, coverage, the emulator's builds) are shared paths that two tests at once
    would configure and build over each other. Subprocesses inherit it."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker and not os.environ.get("FLEETLAB_BUILD_ROOT"):
        os.environ["FLEETLAB_BUILD_ROOT"] = str(REPO_ROOT / "build" / f"pytest-{worker}")


def real_data_path() -> Path:
    """Where the Fleet-To-Lab files are looked for: $FLEETLAB_REAL_DATA, else ../shared/data/fleet_to_lab."""
    env = os.environ.get("FLEETLAB_REAL_DATA")
    return Path(env).expanduser().resolve() if env else DEFAULT_REAL_DATA


def real_data_required() -> bool:
    return os.environ.get("FLEETLAB_REQUIRE_REAL_DATA", "") not in ("", "0")


@pytest.fixture(scope="session")
def real_data_dir() -> Path:
    """The paper's real Fleet-To-Lab files. A clone has none: the tests that need them are skipped, saying how
    to supply them, unless FLEETLAB_REQUIRE_REAL_DATA=1 (CI), where a missing folder is a failure."""
    path = real_data_path()
    present = path.is_dir() and any(path.glob("*.csv"))
    if not present:
        msg = f"Fleet-To-Lab files not found at {path}: {HOW_TO_SUPPLY}"
        if real_data_required():
            pytest.fail(f"FLEETLAB_REQUIRE_REAL_DATA is set but {msg}", pytrace=False)
        pytest.skip(msg)
    return path


# --------------------------------------------------------------- the CANopen node tests' builds and models
@pytest.fixture(scope="module")
def bdir() -> Path:
    """The host build holding the emulator process and the in-process library (the CANopen node's two links)."""
    from fleetlab.host_tools.emulator import EMULATOR_TARGET, HOST_LIBRARY_TARGET, build

    return build(None, targets=(EMULATOR_TARGET, HOST_LIBRARY_TARGET))


@pytest.fixture(scope="module")
def new_bundle(tmp_path_factory) -> Path:
    """A second, different SN-S exported as model version 2 (the model to upload)."""
    from fleetlab.export.bundle import export_bundle
    from fleetlab.export.vectors import draw_inputs
    from small_models import small_model

    out = tmp_path_factory.mktemp("canopen") / "new"
    export_bundle(small_model(seed=9), out, inputs=draw_inputs(200, None, seed=3), model_version=2)
    return out


@pytest.fixture(scope="module")
def samples():
    """100 windows of simulated raw telemetry (int16, DBC channel order) to stream to the node."""
    from fleetlab.host_tools.sources import sim_source

    return sim_source(0, 0.05).samples_q[: 100 * 12]
