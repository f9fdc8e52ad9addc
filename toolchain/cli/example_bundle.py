"""`python -m fleetlab.cli.example_bundle [--out DIR] [--seed 1] [--scale 0.3]`: the maintainer's command that
regenerates the committed example bundle with `fleetlab.export.example.make_example`.

Not a `fleetlab` subcommand: a user exports their own model with `fleetlab export`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fleetlab.export import example
from ..models.train import EXPERT_EPOCHS
from ..paths import default_bundle


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m fleetlab.cli.example_bundle",
                                description=example.__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=None,
                   help="bundle directory (default: the committed example bundle, firmware_c/bundles/example)")
    p.add_argument("--seed", type=int, default=1, help="simulator and training seed (default 1)")
    p.add_argument("--scale", type=float, default=0.3, help="simulator scale (default 0.3)")
    p.add_argument("--epochs", type=int, default=EXPERT_EPOCHS, help=f"training epochs (default {EXPERT_EPOCHS})")
    p.add_argument("--keep", type=Path, help="also keep the trained model and the simulated data in this folder")
    args = p.parse_args(argv)
    out = example.make_example(args.out or default_bundle(), args.seed, args.scale, args.epochs, args.keep)
    print(f"example bundle written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
