#!/usr/bin/env bash
# Sets up a fresh machine (system packages, .venv with the torch CPU wheel and fleetlab) and runs the full
# test suite from that venv: Python tests, the C builds and ctest (host with sanitizers, cross targets under
# QEMU), fuzzing, a demo run. Extra arguments go to pytest (e.g. bash scripts/test.sh -k firmware -x).
#
# Tests that need the Fleet-To-Lab files read them from $FLEETLAB_REAL_DATA (default ../shared/data/fleet_to_lab)
# and are skipped when it is absent, unless FLEETLAB_REQUIRE_REAL_DATA=1 (then a missing folder fails).
#
# Two pytest workers (pytest-xdist), one test file at a time each (--dist loadfile: a file's module fixtures, its
# builds and exports, are made once): most tests wait on one single-threaded tool (QEMU, cppcheck, Frama-C, a
# compiler), so the serial suite kept about one of two cores busy. FLEETLAB_TEST_WORKERS=N sets the count; 0 runs
# the tests in this process, one after the other. Each worker builds under its own build root (tests/conftest.py).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/venv.sh
activate_fleetlab_venv
python -m pytest -n "${FLEETLAB_TEST_WORKERS:-2}" --dist loadfile "$@"
