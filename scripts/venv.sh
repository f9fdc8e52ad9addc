# Sourced by the scripts: where fleetlab's virtual environment is, and its bin/ first on PATH so that
# `fleetlab`, `python` and CMake's find_package(Python3) all mean the venv's interpreter.
FLEETLAB_VENV="${FLEETLAB_VENV:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/.venv}"
export FLEETLAB_VENV
activate_fleetlab_venv() {
  export VIRTUAL_ENV="$FLEETLAB_VENV"
  export PATH="$FLEETLAB_VENV/bin:$PATH"
  export PYTHON="$FLEETLAB_VENV/bin/python"
}
# pip install into the given interpreter, quiet, without the noise of this machine's local wheel indexes
# (missing index folders) and of crcmod's legacy setup.py; real errors still reach stderr.
pip_install() {
  local py="$1"; shift
  "$py" -m pip install -q --disable-pip-version-check "$@" \
    2> >(grep -v -e "is ignored: it is neither" -e "DEPRECATION: crcmod" >&2)
}
