#!/usr/bin/env bash
# Installs everything fleetlab needs on a fresh Debian machine, then the project itself.
# Idempotent: packages already present are skipped by apt/pip.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES="cmake gcc g++ clang libclang-rt-14-dev gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm"
missing=""
for p in $APT_PACKAGES; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi

PY=${PYTHON:-python3}
# The CPU wheel of torch first, so that no dependency pulls a CUDA build.
$PY -c "import torch, sys; sys.exit(0 if torch.__version__.startswith('2.13.0') else 1)" 2>/dev/null \
  || $PY -m pip install -q torch==2.13.0
$PY -m pip install -q -e ".[test]"
