#!/usr/bin/env bash
# Refreshes requirements.lock: resolves fleetlab's dependencies (with the test extras) afresh in a throw-away
# venv, from the same torch CPU wheel, and writes every resolved version. Run the suite after refreshing.
#   bash scripts/lock.sh && bash scripts/test.sh
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY=${PYTHON:-python3}
TMP=$(mktemp -d); trap 'rm -rf "$TMP"' EXIT
"$PY" -m venv "$TMP/venv"
# shellcheck source=scripts/venv.sh
source "$ROOT/scripts/venv.sh"
pip_install "$TMP/venv/bin/python" torch==2.13.0
pip_install "$TMP/venv/bin/python" "$ROOT[test]"
{
  echo "# Versions the test suite passed with; scripts/setup.sh installs exactly these (pip -c)."
  echo "# Refresh: bash scripts/lock.sh  (then run bash scripts/test.sh before committing)"
  echo "# Python $("$TMP/venv/bin/python" -c 'import sys; print(sys.version.split()[0])'), $(uname -m), $(date -u +%Y-%m-%d)"
  "$TMP/venv/bin/python" -m pip freeze --disable-pip-version-check --exclude fleetlab | LC_ALL=C sort -f
} > "$ROOT/requirements.lock"
echo "wrote $ROOT/requirements.lock ($(grep -vc '^#' "$ROOT/requirements.lock") packages)"
