"""Shared pytest fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
REAL_DATA = REPO_ROOT.parent / "shared" / "data" / "fleet_to_lab"


@pytest.fixture(scope="session")
def real_data_dir() -> Path:
    """The paper's real Fleet-To-Lab files, which CI and developers have beside the repo."""
    assert REAL_DATA.is_dir(), f"expected the Fleet-To-Lab files at {REAL_DATA} (../shared/data/fleet_to_lab)"
    return REAL_DATA
