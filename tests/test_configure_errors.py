"""A CMake configure that cannot succeed says why at configure time, in CMake's own words, not as a Python
traceback halfway through the build (issue 42, item 7)."""

from __future__ import annotations

import subprocess
import sys
import venv
from pathlib import Path

from required import need_tool

REPO = Path(__file__).resolve().parents[1]


def test_a_python_without_cantools_is_refused_at_configure(tmp_path):
    cmake = need_tool("cmake")
    bare = tmp_path / "bare"
    venv.EnvBuilder(with_pip=False, system_site_packages=False).create(bare)  # a Python with no cantools
    python = bare / "bin" / "python"
    assert subprocess.run([str(python), "-c", "import cantools"], capture_output=True).returncode != 0
    res = subprocess.run([cmake, "-S", str(REPO), "-B", str(tmp_path / "b"), f"-DPython3_EXECUTABLE={python}"],
                         capture_output=True, text=True, timeout=300)
    err = " ".join(res.stderr.split())  # CMake wraps its messages
    assert res.returncode != 0 and "cannot import cantools" in err and "-DPython3_EXECUTABLE=" in err, err
    assert "Traceback" not in res.stdout + res.stderr
    # the same configure with this interpreter (which has cantools) gets past the check
    ok = subprocess.run([cmake, "-S", str(REPO), "-B", str(tmp_path / "ok"), f"-DPython3_EXECUTABLE={sys.executable}"],
                        capture_output=True, text=True, timeout=300)
    assert "cannot import cantools" not in ok.stderr
