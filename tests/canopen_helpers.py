"""What the CANopen node tests share: the node id, the boot bundle, the model a test uploads, and the reference
its estimates must equal (tests/test_canopen_node.py, test_canopen_upload_faults.py, test_upload_cli.py; the
fixtures that build them are in conftest.py)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from fleetlab.data import features_int as fi
from fleetlab.export.bundle import export_bundle
from fleetlab.export.vectors import draw_inputs
from fleetlab.host_tools.verify.reference import Reference

from small_models import small_model

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"  # the node's boot model (version 1)
NODE_ID = 5


def export_upload_bundle(out: Path) -> Path:
    """A second, different SN-S exported as model version 2 (the model to upload)."""
    export_bundle(small_model(seed=9), out, inputs=draw_inputs(200, None, seed=3), model_version=2)
    return out


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
