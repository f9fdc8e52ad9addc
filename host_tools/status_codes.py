"""The C library's status codes (slipest_status_t), read from their one source,
firmware_c/include/slipest_status.h, instead of being retyped: `status()["SLIPEST_E_NVM"] == -14` (read on first
use, not at import: importing fleetlab reads no file)."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

from fleetlab.paths import repo_root
from fleetlab.errors import InputError

_ENTRY = re.compile(r"^\s*(SLIPEST_(?:OK|E_[A-Z_]+))\s*=\s*(-?\d+)\s*,?", re.MULTILINE)


def header() -> Path:
    return repo_root() / "firmware_c" / "include" / "slipest_status.h"


@cache
def status() -> dict[str, int]:
    """slipest_status_t's names and values."""
    text = header().read_text(encoding="utf-8")
    body = text[text.index("typedef enum {"):text.index("} slipest_status_t;")]
    codes = {name: int(value) for name, value in _ENTRY.findall(body)}
    if "SLIPEST_OK" not in codes or len(set(codes.values())) != len(codes):
        raise InputError(f"{header()}: cannot read slipest_status_t")
    return codes



_MEANING = re.compile(r"^\s*(SLIPEST_(?:OK|E_[A-Z_]+))\s*=\s*(-?\d+)\s*,?\s*/\*\*<\s*(.*?)\s*\*/", re.MULTILINE)


@cache
def meanings() -> dict[int, tuple[str, str]]:
    """value -> (name, meaning) of each status code, the meaning being its comment in slipest_status.h
    (`meanings()[-16] == ("SLIPEST_E_STALE", "model version not newer than the active one (not a rollback)")`)."""
    text = header().read_text(encoding="utf-8")
    body = text[text.index("typedef enum {"):text.index("} slipest_status_t;")]
    out = {int(value): (name, doc) for name, value, doc in _MEANING.findall(body)}
    if set(out) != set(status().values()):
        raise InputError(f"{header()}: a status code without its /**< meaning */ comment")
    return out
