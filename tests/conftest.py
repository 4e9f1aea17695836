"""Shared fixtures: where the shared CMU clips are (tests/shared_data.py; SAMBA_CMU_DIR or ../shared)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.shared_data import CMU_DIR, CMU_SKIP

SHARED = CMU_DIR


@pytest.fixture(scope="session")
def cmu_dir() -> Path:
    """The CMU clips folder (``SAMBA_CMU_DIR`` or ``../shared/data/cmu-bvh``), else skip saying where."""
    if not CMU_DIR.is_dir():
        pytest.skip(CMU_SKIP)
    return CMU_DIR
