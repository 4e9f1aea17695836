"""Shared fixtures: where the shared CMU clips are (skipped tests name it when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cmu-bvh"


@pytest.fixture(scope="session")
def cmu_dir() -> Path:
    if not SHARED.is_dir():
        pytest.skip(f"shared CMU clips not found at {SHARED}")
    return SHARED
