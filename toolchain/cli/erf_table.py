"""`python -m fleetlab.cli.erf_table [--check]`: the maintainer's command that regenerates the float kernel's erf
header (`firmware_c/src/slipest_erf_f32.h`) from `fleetlab.export.erf_table`, or prints its max error.

Not a `fleetlab` subcommand: a user never needs it; tests/test_erf_table.py checks the committed header.
"""

from __future__ import annotations

import argparse
import sys

from fleetlab.export import erf_table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fleetlab.cli.erf_table", description=erf_table.__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="print the float32 evaluation's max |error| instead")
    args = ap.parse_args(argv)
    print(f"max |erf_f32 - erf| = {erf_table.max_error():.3g}" if args.check else erf_table.header(),
          end="\n" if args.check else "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
