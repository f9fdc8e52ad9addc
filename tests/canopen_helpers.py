"""What the CANopen node tests share (tests/test_canopen_node.py, test_canopen_upload_faults.py,
test_upload_cli.py): the node id, the boot bundle, and the reference its estimates must equal. The fixtures
they use (the build, the model to upload, the telemetry) are in conftest.py."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from fleetlab.data import features_int as fi
from fleetlab.host_tools.verify.reference import Reference

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"  # the node's boot model (version 1)
NODE_ID = 5


def expected_logits(bundle: Path, samples: np.ndarray) -> np.ndarray:
    logits, _ = Reference.load(bundle).q_logits(fi.featurise_int(samples).features)
    return logits


def wait_emcy(node, code: int, timeout: float = 2.0) -> bool:
    """True when the node's EMCY log (python canopen's EMCY consumer) holds `code`."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:  # safety net: the wait ends on the EMCY, False when it never comes
        if any(e.code == code for e in node.emcy.log):
            return True
        time.sleep(0.01)
    return False
