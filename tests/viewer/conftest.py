"""Shared helpers for the viewer tests: a running Viewer fed by a bounded publisher thread."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from samba_common.skeleton import MARKER_JOINT
from samba_server.viewer import Viewer


def standing_pose(k: int) -> np.ndarray:
    """(13, 3) world metres of a person standing at the origin, arms swinging with k."""
    a = 0.4 * np.sin(k / 10)
    return np.array([
        [0, 0, 1.70], [-0.18, 0, 1.45], [0.18, 0, 1.45], [-0.22, 0.3 * a, 1.17], [0.22, -0.3 * a, 1.17],
        [-0.25, 0.5 * a, 0.92], [0.25, -0.5 * a, 0.92], [-0.12, 0, 0.95], [0.12, 0, 0.95],
        [-0.12, -0.2 * a, 0.52], [0.12, 0.2 * a, 0.52], [-0.12, -0.3 * a, 0.09], [0.12, 0.3 * a, 0.09]])


class Publisher:
    """Publishes poses, blobs of two motes and a status at ``rate`` Hz for at most ``seconds``."""

    def __init__(self, viewer: Viewer, seconds: float = 20.0, rate: float = 30.0):
        self.viewer, self.seconds, self.rate = viewer, seconds, rate
        self.count = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        end = time.monotonic() + self.seconds
        while not self._stop.is_set() and time.monotonic() < end:
            j = standing_pose(self.count)
            self.viewer.publish_pose(self.count / self.rate, j, j[list(MARKER_JOINT)],
                                     {"residual_m": 0.004, "n_markers": 8})
            for m, (du, dv) in (("cam0", (60, 10)), ("cam1", (90, 14))):
                uv = np.c_[du + 40 * j[list(MARKER_JOINT), 0], dv + 60 * (1.8 - j[list(MARKER_JOINT), 2])]
                self.viewer.publish_blobs(m, uv, np.arange(8), (160, 120))
            if self.count % 10 == 0:
                self.viewer.publish_status({"motes": {"cam0": {"alive": True, "fps": 60.0, "blobs": 8, "drops": 0},
                                                      "cam1": {"alive": False, "fps": 0.0, "blobs": 0, "drops": 3}},
                                            "fps": 59.9, "latency_ms": 2.5, "drops": 3, "recording": False})
            self.count += 1
            time.sleep(1.0 / self.rate)

    def __enter__(self) -> "Publisher":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)


@pytest.fixture
def viewer():
    """A started Viewer on a free loopback port, with an on_record log in ``viewer.calls``."""
    calls: list[bool] = []
    v = Viewer("127.0.0.1", 0, on_record=calls.append)
    v.calls = calls  # type: ignore[attr-defined]
    v.start()
    yield v
    v.stop()
