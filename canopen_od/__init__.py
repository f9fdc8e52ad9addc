"""The slipest CANopen node's object dictionary: `objects` is the one source of the C tables and
of the EDS (`generate`). Shared by the C build (CMake runs generate.py as a script) and the host
tools (`fleetlab.canopen_od`)."""

from . import objects
from .generate import eds_text

__all__ = ["eds_text", "objects"]
