#!/usr/bin/env bash
# Installs everything fleetlab needs on a fresh Debian/Ubuntu machine: the system packages, then a virtual
# environment in the clone (.venv) holding the torch CPU wheel and fleetlab, at the versions pinned in
# requirements.lock. It works whatever python3 is first on PATH (the distribution's, pyenv's, conda's):
# nothing is installed into that interpreter itself, so PEP 668 ("externally-managed-environment") never applies.
#
#   PYTHON=/path/to/python3.11 bash scripts/setup.sh    # pick the interpreter the venv is made from
#   FLEETLAB_VENV=/some/dir bash scripts/setup.sh       # put the venv elsewhere (default: <clone>/.venv)
#
# Idempotent: packages already present are skipped by apt and pip.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# shellcheck source=scripts/venv.sh
source scripts/venv.sh

need_apt() { for p in "$@"; do dpkg -s "$p" >/dev/null 2>&1 || printf ' %s' "$p"; done; }
# first word of each line: the package (the words after it name its commands, for tests/required.py)
APT_PACKAGES=$(grep -v '^[[:space:]]*#' scripts/apt-packages.txt | awk 'NF {print $1}' | tr '\n' ' ')
missing=$(need_apt $APT_PACKAGES)
PY=${PYTHON:-python3}
# a venv needs ensurepip, which Debian ships separately (python3-venv / python3.X-venv)
if ! "$PY" -c "import ensurepip, venv" 2>/dev/null; then
  ver=$("$PY" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
  missing="$missing python3-venv python$ver-venv"
fi
if [ -n "${missing// /}" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "setup: apt-get install$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

if [ ! -x "$FLEETLAB_VENV/bin/python" ]; then
  echo "setup: creating $FLEETLAB_VENV from $("$PY" -c 'import sys; print(sys.executable, sys.version.split()[0])')"
  "$PY" -m venv "$FLEETLAB_VENV"
fi
VPY="$FLEETLAB_VENV/bin/python"
# The torch CPU wheel first, so that no dependency pulls a CUDA build; then everything at the locked versions.
"$VPY" -c "import torch, sys; sys.exit(0 if torch.__version__.startswith('2.13.0') else 1)" 2>/dev/null \
  || pip_install "$VPY" torch==2.13.0
pip_install "$VPY" -c requirements.lock -e ".[test]"
echo "setup: ready ($("$VPY" -c 'import sys, torch; print("python", sys.version.split()[0], "torch", torch.__version__)')); source $FLEETLAB_VENV/bin/activate to put fleetlab on PATH"
