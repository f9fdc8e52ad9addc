"""Remove the floating-point helpers from cantools-generated C so the codec is integer-only.

cantools' ``--no-floating-point-numbers`` drops encode/decode, but still emits
``*_is_in_phys_range(double)`` checks. Those pull soft-float routines (``__aeabi_dcmp*``)
into the fixed-point archive on FPU-less cores, so the build removes them (definition,
declaration and its doc comment) and then refuses any remaining ``float``/``double``.

    python host_tools/dbc_fixed_point.py GEN/slipest_dbc.c GEN/slipest_dbc.h   (in place)
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

# a definition: signature line, then a brace block without nested braces
_DEFINITION = re.compile(r"^bool \w+_is_in_phys_range\(double value\)\n\{\n[^{}]*?\n\}\n\n?", re.M)
# a declaration with the Doxygen block that precedes it
_DECLARATION = re.compile(r"^/\*\*\n(?: \*[^\n]*\n)*? \*/\nbool \w+_is_in_phys_range\(double value\);\n\n?", re.M)
_FLOAT_WORD = re.compile(r"\b(double|float)\b")


def strip(text: str) -> tuple[str, int]:
    """Return text without the phys-range helpers, and how many were removed."""
    text, n_def = _DEFINITION.subn("", text)
    text, n_decl = _DECLARATION.subn("", text)
    return text, n_def + n_decl


def main(paths: list[str]) -> int:
    if not paths:
        print(__doc__, file=sys.stderr)
        return 2
    for name in paths:
        path = Path(name)
        text, removed = strip(path.read_text())
        left = [m.group(0) for m in _FLOAT_WORD.finditer(re.sub(r"/\*.*?\*/", "", text, flags=re.S))]
        if left:
            print(f"dbc_fixed_point: {path} still uses {sorted(set(left))} after stripping "
                  f"{removed} helpers (cantools output changed?)", file=sys.stderr)
            return 1
        path.write_text(text)
        print(f"dbc_fixed_point: {path}: removed {removed} floating-point helpers")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
