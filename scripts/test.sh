#!/usr/bin/env bash
# Sets up a fresh machine (system packages, torch CPU wheel, fleetlab) and runs the full test suite:
# Python tests, the C builds and ctest (host with sanitizers, Cortex-M4/M3 under QEMU), fuzzing, a demo run.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
python3 -m pytest "$@"
