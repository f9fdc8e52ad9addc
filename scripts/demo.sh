#!/usr/bin/env bash
# Sets up a fresh machine and runs the whole pipeline on built-in defaults (simulator, no external data),
# from the clone's .venv. The report lands in demo_out/report.md (and report.html).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
source scripts/venv.sh
activate_fleetlab_venv
fleetlab demo --out "${1:-demo_out}"
