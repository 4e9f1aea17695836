"""Shared fixtures of the server tests: a short take with the standard pose, free ports, and
whether the machine is overloaded (timing-sensitive live checks are made only when it is not)."""

from __future__ import annotations

import os
import socket
from importlib.resources import files

import numpy as np
import pytest


def free_endpoint() -> str:
    """A ``tcp/127.0.0.1:PORT`` endpoint on a free port."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def overloaded() -> bool:
    """The 1-minute load average is at or above the core count: other work on the box (a
    benchmark beside the tests) delays packets and solves by more than the live checks allow."""
    return os.getloadavg()[0] >= (os.cpu_count() or 1)


def short_take(seconds: float = 0.6, fps: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """The shipped demo clip's first ``seconds``, preceded by the standard pose (1.6 s)."""
    from samba_mote.sim.tpose import prepend_tpose

    with files("samba_common").joinpath("data", "demo_take.npz").open("rb") as fh, np.load(fh) as z:
        joints, t = z["joints"].astype(float), z["t"].astype(float)
    step = max(int(round(60.0 / fps)), 1)  # the clip is at 60 fps
    n = int(round(seconds * 60.0))
    j, t, _ = prepend_tpose(joints[:n:step], t[:n:step], fps)
    return j, t


@pytest.fixture
def endpoint() -> str:
    return free_endpoint()
