"""Shared fixtures for the mote tests: free TCP ports, small simulated takes."""

from __future__ import annotations

import socket

import pytest


@pytest.fixture
def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def small_take(tmp_path_factory):
    """A 2-camera, 2-second synthetic take on disk (plus the 1.6 s T-pose lead-in)."""
    from samba_mote.sim import SimConfig, make_take

    return make_take(tmp_path_factory.mktemp("take"), None, rig=2, seconds=2.0, seed=3,
                     config=SimConfig(tpose_stance="apart", pose_at=None))
