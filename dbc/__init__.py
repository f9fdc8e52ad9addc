"""The estimator's CAN database (`slipest.dbc`) and its layout check.

This folder is shared by the C build (CMake generates the C codec from the DBC and runs
`layout.py check` on a rover's own copy) and the host tools (`fleetlab.dbc`, package data):
neither side reaches into the other's folder for it.
"""

from .layout import DBC_PATH, check_layout, layout_of, load

__all__ = ["DBC_PATH", "check_layout", "layout_of", "load"]
