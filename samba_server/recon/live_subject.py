"""Live subject calibration: skin-marker offsets and bone lengths measured after the standard pose.

A :class:`~samba_server.recon.reconstruct.Reconstructor` built without a subject (the server
without ``--subject``, ``samba-replay``, ``samba-process``) decides the marker placement from
the standard pose (:func:`.subject_model.placement_from_standard_pose`). With skin markers it
solves with the typical landmark offsets and the standard-pose lengths, collects the solved
frames (markers + torso rotation, shoulder midpoint, bone directions) for
``subject_seconds`` of frame time, and computes one :func:`.subject_model.linear_update` from
them; a second update from the next ``subject_refine_seconds`` follows (the first subject's
poses). Each update and the database re-posed with it are computed in a background thread and
swapped in exactly ``subject_swap_frames`` solves later, so no frame waits and a replay of the
recording takes every step at the same frame: live, replay and ``samba-process`` give the
same poses.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from samba_common.markerset import OFFSET_SIGMA
from samba_common.skeleton import BONE_TYPES, MARKER_NAMES
from samba_common.subject import Subject

from .subject_model import decorrelation, linear_update

log = logging.getLogger(__name__)

#: most frames one update uses (an even subsample of more)
MAX_FRAMES = 600


def describe(subject: Subject) -> str:
    """One-line summary: lengths (m) and offsets +- sigma (mm) of a subject."""
    lens = ", ".join(f"{n} {v:.3f}" for n, v in zip(BONE_TYPES, subject.lengths))
    sig = subject.offsets_sigma if subject.offsets_sigma is not None else np.full_like(subject.offsets, np.nan)
    offs = "; ".join(f"{n} [{', '.join(f'{1000 * v:+.0f}' for v in o)}] +- {1000 * float(np.max(e)):.0f}"
                     for n, o, e in zip(MARKER_NAMES, subject.offsets, sig))
    return f"{subject.placement}: lengths (m) {lens}; offsets (mm, e1 e2 e3, +- largest 1 sigma) {offs}"


@dataclass
class _Stage:
    """Frames collected for one update: markers (8, 3), t, R (3, 3), o (3,), dirs (11, 3), residual."""

    seconds: float
    frames: list[tuple] = field(default_factory=list)


class LiveSubjectCalibration:
    """The state machine above. ``build(lengths, offsets)`` returns what the reconstructor swaps
    in (its re-posed index); ``swap(subject, built)`` installs it. lengths0: (8,) standard-pose
    lengths (the prior centre, m)."""

    def __init__(self, lengths0: np.ndarray, seconds: tuple[float, ...], swap_frames: int,
                 build: Callable[[np.ndarray, np.ndarray], object], swap: Callable[[Subject, object], None]):
        self.lengths0 = np.asarray(lengths0, float).copy()
        self._stages = [_Stage(s) for s in seconds if s > 0]
        self._swap_frames = max(int(swap_frames), 1)
        self._build, self._swap = build, swap
        self._pending: tuple[threading.Thread, dict] | None = None
        self._countdown = 0

    @property
    def done(self) -> bool:
        """True when every update has been swapped in."""
        return not self._stages and self._pending is None

    def step(self, markers: np.ndarray, t: float, status: str, residual: float,
             state: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> None:
        """Call after every solve: markers (8, 3) world m, t s, the result's status, residual (m)
        and state (R, o, dirs)."""
        if self._pending is not None:
            self._countdown -= 1
            if self._countdown <= 0:
                worker, box = self._pending
                worker.join()
                self._pending = None
                if "error" in box:
                    log.warning("live subject calibration failed (%s): keeping the current subject", box["error"])
                else:
                    self._swap(box["subject"], box["built"])
            return
        if not self._stages:
            return
        stage = self._stages[0]
        if status == "solved" and state is not None:
            R, o, d = state
            stage.frames.append((np.array(markers, float), float(t), R.copy(), o.copy(), d.copy(), float(residual)))
        if stage.frames and t - stage.frames[0][1] >= stage.seconds and len(stage.frames) >= 10:
            self._stages.pop(0)
            box: dict = {}
            worker = threading.Thread(target=self._compute, args=(stage.frames, box), daemon=True,
                                      name="samba-subject")
            worker.start()
            self._pending, self._countdown = (worker, box), self._swap_frames

    def _compute(self, frames: list[tuple], box: dict) -> None:
        """(background) One linear update from ``frames`` and the index re-posed with it."""
        try:
            step = max(1, int(np.ceil(len(frames) / MAX_FRAMES)))
            frames = frames[::step]
            markers = np.array([f[0] for f in frames])
            t = np.array([f[1] for f in frames])
            R = np.array([f[2] for f in frames])
            o = np.array([f[3] for f in frames])
            dirs = np.array([f[4] for f in frames])
            res = np.array([f[5] for f in frames])
            sigma = max(float(np.sqrt(np.nanmean(np.square(res)))), 0.003)
            lengths, offsets, _sl, sig_o = linear_update(markers, R, o, dirs, self.lengths0, sigma, decorrelation(t))
            subject = Subject(lengths, offsets, np.minimum(sig_o, OFFSET_SIGMA), "skin")
            box["built"] = self._build(lengths, offsets)
            box["subject"] = subject
            box["frames"] = len(frames)
        except Exception as exc:  # never kill the live thread: keep the current subject
            box["error"] = f"{type(exc).__name__}: {exc}"


__all__ = ["LiveSubjectCalibration", "describe"]
