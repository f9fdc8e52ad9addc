"""Where the firmware sources are: the source tree this package was installed from (editable install)."""

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_BUNDLE = REPO / "firmware_c" / "bundles" / "example"
