"""The C library's status codes (slipest_status_t), read from their one source,
firmware_c/include/slipest_status.h, instead of being retyped: `STATUS["SLIPEST_E_NVM"] == -14`."""

from __future__ import annotations

import re

from fleetlab.paths import repo_root

HEADER = repo_root() / "firmware_c" / "include" / "slipest_status.h"
_ENTRY = re.compile(r"^\s*(SLIPEST_(?:OK|E_[A-Z_]+))\s*=\s*(-?\d+)\s*,?", re.MULTILINE)


def _read() -> dict[str, int]:
    text = HEADER.read_text(encoding="utf-8")
    body = text[text.index("typedef enum {"):text.index("} slipest_status_t;")]
    codes = {name: int(value) for name, value in _ENTRY.findall(body)}
    if "SLIPEST_OK" not in codes or len(set(codes.values())) != len(codes):
        raise ValueError(f"{HEADER}: cannot read slipest_status_t")
    return codes


STATUS: dict[str, int] = _read()
