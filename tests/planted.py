"""Negative controls of the analysers: the library's sources with one defect planted.

Each control copies firmware_c/src into a scratch folder, replaces one line of one file there, and runs the
analyser on the copy; the line must be in the real source, so a control never plants into nothing.
"""

from __future__ import annotations

from pathlib import Path

from fleetlab.assurance.sources import fw


def planted_src(dest: Path, file: str, real: str, planted: str) -> Path:
    """firmware_c/src copied into `dest`, with `real` (asserted present in `file`) replaced by `planted`."""
    src_dir = fw() / "src"
    text = (src_dir / file).read_text()
    assert real in text, f"{file} no longer holds the line this control plants into: {real}"
    for f in src_dir.iterdir():
        (dest / f.name).write_bytes(f.read_bytes())
    (dest / file).write_text(text.replace(real, planted))
    return dest
