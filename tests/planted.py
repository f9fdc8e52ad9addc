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


# The layer-table kernel's clamp of e to 2^14 in centre_pass (slipest_infer_table_q.c), and the same line without
# it: EVA must then report e_ * e_ (tests/test_export_arch.py, scripts/eva_at_caps.py).
LAYER_E_CLAMP = "SAT(rsr_h(SAT(nh * hp_ - sum, 30), half, k2), 14)"
LAYER_E_UNCLAMPED = "rsr_h(SAT(nh * hp_ - sum, 30), half, k2)"
