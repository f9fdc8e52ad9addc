"""Layout check of a rover's DBC against the reference `slipest.dbc` (only frame IDs may differ).

Kept free of fleetlab imports: the firmware build runs this file as a script
(`python dbc/layout.py check FILE`) with nothing but cantools installed.
"""

from __future__ import annotations

import argparse
import sys
from functools import lru_cache
from pathlib import Path

import cantools

DBC_PATH = Path(__file__).with_name("slipest.dbc")  # the reference layout and the default DBC


@lru_cache(maxsize=4)
def load(path: Path) -> cantools.database.can.Database:
    """Parse a DBC file; any parser failure becomes one ValueError naming the file."""
    try:
        return cantools.database.load_file(str(path))
    except Exception as e:  # cantools raises several parser-specific types
        raise ValueError(f"{path}: not a readable DBC file: {e}") from None


def layout_of(db: cantools.database.can.Database) -> dict[str, tuple]:
    """Everything the estimator relies on, per message: length, senders, and each signal's
    name, position, size, byte order, sign, scale and offset. Frame IDs are left out."""
    return {
        m.name: (m.length, tuple(sorted(m.senders)), tuple(
            (s.name, s.start, s.length, s.byte_order, s.is_signed, s.scale, s.offset)
            for s in sorted(m.signals, key=lambda s: s.start)))
        for m in db.messages
    }


def check_layout(db: cantools.database.can.Database, source: str) -> None:
    """Refuse a DBC that differs from the reference in anything but frame IDs (and comments).

    The C node and the host tools hard-wire message names and signal layouts; only the IDs
    are free. IDs must be 11-bit and distinct."""
    ref, got = layout_of(load(DBC_PATH.resolve())), layout_of(db)
    problems = [f"message {n} missing" for n in ref if n not in got]
    problems += [f"message {n} is not in dbc/slipest.dbc" for n in got if n not in ref]
    problems += [f"{n}: layout differs from dbc/slipest.dbc (length, senders or signals)"
                 for n in ref if n in got and got[n] != ref[n]]
    ids = [m.frame_id for m in db.messages]
    problems += [f"{m.name}: ID 0x{m.frame_id:X} is not an 11-bit standard ID"
                 for m in db.messages if m.is_extended_frame or not 0 <= m.frame_id <= 0x7FF]
    problems += [f"ID 0x{i:03X} used by more than one message" for i in sorted(set(ids)) if ids.count(i) > 1]
    if problems:
        raise ValueError(f"{source}: incompatible with the estimator: " + "; ".join(problems))


def main(argv: list[str] | None = None) -> int:
    """`python dbc/layout.py check FILE`: the CMake build's gate for `-DSLIPEST_DBC`."""
    p = argparse.ArgumentParser(description="check that a DBC keeps the layout of dbc/slipest.dbc "
                                            "(only frame IDs may differ)")
    p.add_argument("command", choices=["check"])
    p.add_argument("dbc", type=Path)
    args = p.parse_args(argv)
    path = args.dbc.expanduser().resolve()
    try:
        if not path.is_file():
            raise OSError(f"{path}: no such DBC file")
        check_layout(load(path), path.name)
    except (ValueError, OSError) as e:
        print(f"slipest DBC check: {e}", file=sys.stderr)
        return 1
    print(f"{args.dbc}: layout matches dbc/slipest.dbc")
    return 0


if __name__ == "__main__":
    sys.exit(main())
