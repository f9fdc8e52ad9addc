"""The public C headers build under Doxygen without a single warning (undocumented function,
parameter or return value fail the build: WARN_AS_ERROR, WARN_NO_PARAMDOC in firmware_c/Doxyfile)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from required import need_tool

REPO = Path(__file__).resolve().parents[1]
INCLUDE = REPO / "firmware_c" / "include"


def run_doxygen(input_dir: Path, out: Path) -> subprocess.CompletedProcess:
    need_tool("doxygen")
    # the project's Doxyfile, with the input and output directories overridden on stdin
    cfg = (REPO / "firmware_c" / "Doxyfile").read_text() + f"\nINPUT = {input_dir}\nOUTPUT_DIRECTORY = {out}\n"
    return subprocess.run(["doxygen", "-"], input=cfg, cwd=REPO, capture_output=True, text=True, timeout=120)


def test_public_headers_are_fully_documented(tmp_path) -> None:
    res = run_doxygen(INCLUDE, tmp_path / "doc")
    assert res.returncode == 0 and "warning" not in res.stderr.lower() and "error" not in res.stderr.lower(), res.stderr
    assert (tmp_path / "doc" / "html" / "index.html").is_file()


def test_an_undocumented_parameter_fails_the_build(tmp_path) -> None:
    """The check can fail: one @param line removed from a copy of the headers is reported."""
    copy = tmp_path / "include"
    shutil.copytree(INCLUDE, copy)
    h = copy / "slipest_infer.h"
    text = h.read_text()
    line = " * @param[out] saturations  if not NULL, receives the number of saturation events of this call\n"
    assert line in text
    h.write_text(text.replace(line, ""))
    res = run_doxygen(copy, tmp_path / "doc")
    assert res.returncode != 0 and "saturations" in res.stderr, res.stderr


def test_every_public_header_has_cplusplus_guards() -> None:
    for h in sorted(INCLUDE.glob("*.h")):
        text = h.read_text()
        assert 'extern "C" {' in text and text.count("#ifdef __cplusplus") == 2, h.name
