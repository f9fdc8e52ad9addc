"""Figures the docs publish, read from the docs themselves, so that a test comparing a measurement with
them fails when the code moves a figure and the docs are not updated in the same commit.

- docs/integrating_slipest.md, "Cost on each CPU target": instructions per inference (fixed-point, float)
  and per telemetry sample of each target (`fleetlab bench c --target all --json`);
- docs/assurance.md, "Worst-case instruction counts": the measured maximum of each function on the
  reference target (`fleetlab assure wcet`)."""

from __future__ import annotations

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"
BAND = 0.10  # a measurement within +-10 % of the published figure


def _table_after(path: Path, heading: str, first_header: str) -> list[dict[str, str]]:
    """Rows (header -> cell) of the first Markdown table after `heading` whose first column is `first_header`."""
    text = path.read_text()
    start = text.index(heading)
    lines = text[start:].splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    header = [c.strip() for c in lines[i].strip("|").split("|")]
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append(dict(zip(header, (c.strip() for c in line.strip("|").split("|")))))
    return rows


def _number(cell: str) -> int | None:
    """The leading figure of a cell ("2,834 (2,762)" -> 2834); None for "n/a"."""
    m = re.match(r"([\d,]+)", cell)
    return int(m[1].replace(",", "")) if m else None


def target_costs() -> dict[str, dict[str, int | None]]:
    """target -> {"q", "f32", "sample"}: instructions per fixed-point / float inference and per sample."""
    rows = _table_after(DOCS / "integrating_slipest.md", "## Cost on each CPU target", "target")
    return {r["target"]: {"q": _number(r["instr./q inference"]), "f32": _number(r["instr./float inference"]),
                          "sample": _number(r["instr./sample (node)"])} for r in rows}


def worst_case_instructions() -> dict[str, int]:
    """function -> the published measured maximum on the reference target."""
    rows = _table_after(DOCS / "assurance.md", "## Worst-case instruction counts", "Function")
    return {r["Function"]: _number(r["Max instructions (Cortex-M4)"]) for r in rows}


def assert_near(measured: float, published: int, what: str) -> None:
    """measured within BAND of the published figure; the message says which doc to update."""
    assert abs(measured - published) <= BAND * published, (
        f"{what}: measured {measured:.0f}, the docs publish {published} (outside +-{BAND:.0%}): fix the "
        f"regression, or re-measure and update the docs in the same commit")
