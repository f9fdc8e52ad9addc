#!/usr/bin/env bash
# Sets up a fresh machine (system packages, .venv with the torch CPU wheel and fleetlab) and runs the full
# test suite from that venv: Python tests, the C builds and ctest (host with sanitizers, cross targets under
# QEMU), fuzzing, a demo run. Extra arguments go to pytest (e.g. bash scripts/test.sh -k firmware -x).
#
# Tests that need the Fleet-To-Lab files read them from $FLEETLAB_REAL_DATA (default ../shared/data/fleet_to_lab)
# and are skipped when it is absent, unless FLEETLAB_REQUIRE_REAL_DATA=1 (then a missing folder fails).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/venv.sh
activate_fleetlab_venv
python -m pytest "$@"
