#!/usr/bin/env bash
# Sets up a fresh machine and runs the whole pipeline on built-in defaults (simulator, no external data).
# The report lands in demo_out/report.md (and report.html).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
fleetlab demo --out "${1:-demo_out}"
