"""`fleetlab assure`: the command-line face of fleetlab.assurance.report."""
from __future__ import annotations

import argparse

from ..assurance.report import add_arguments, assure

__all__ = ["add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    return assure(args)
