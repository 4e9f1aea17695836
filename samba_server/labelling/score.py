"""Scoring the server's marker names against a simulated take's ground truth.

Used by ``benchmarks/labelling.py`` and the tests. A marker counts as *visible* in a frame when
at least two cameras see it apart from every other visible marker (their disks do not touch:
two markers in one blob cannot be told apart by any camera, so they are not counted against
the labelling). A named marker is *right* when it lies within ``tol_m`` of its true position,
or nearer its own true position than any other marker's and within twice ``tol_m`` (a point
between two merged markers, 9-10 cm from each), *wrong* otherwise: a name on a ghost or a
distractor far from every marker is wrong, however far the other markers are (until the
forty-fifth session it counted right when no other marker lay nearer: a still wrist whose
point was lost named on a 2-view ghost 28-34 cm off for 18 frames, both passes alike, 006_07
seed 624).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from samba_common.skeleton import MARKER_JOINT
from samba_server.recon.bounds import CONFIDENT_M

__all__ = ["TELEPORT_M_S", "TELEPORT_S", "TakeScore", "separable_visible", "score_take", "teleports"]

#: a true marker faster than this between two frames (m/s) teleported: the source's glitch
TELEPORT_M_S = 12.0
#: frames this long after a teleport (s) are counted as near it
TELEPORT_S = 0.25


@dataclass
class TakeScore:
    """Figures of one take (frames after the standard-pose lead-in are the *motion*).

    frames: frames scored (outside blackouts, >= 1 visible marker); correct: share of them
    with every visible marker named right and no wrong name; wrong_frames: frames with a wrong
    name; confident_wrong: share of confident frames (a pose solved from >= 4 named markers, not
    bridged across missing markers) with a joint more than 20 cm off; confident_wrong_marker: the
    same for the 8 joints that carry a marker (the solver fits those to the markers within a few
    cm, so one 20 cm off was put there by a wrong name; the other joints also carry what the
    solver alone gets wrong); bound_wrong: share of confident frames with a joint more than
    20 cm off whose own bound (:mod:`samba_server.recon.bounds`) claimed it within 20 cm (a
    *confidently* wrong joint); unsure_joints: share of the joints of confident frames whose
    bound is 20 cm or more (drawn, but flagged as a guess);
    solved: share of frames outside blackouts with a pose; reacquire_s: per blackout, the time
    from the markers' return to the first frame with >= 6 markers named right (NaN if never);
    blackout_pose_s: the longest time into a blackout with a pose still output; mpjpe_m: mean
    joint error of the solved motion frames; near_teleport: scored frames not all right within
    :data:`TELEPORT_S` after a *teleport* of the ground truth (a true marker moving faster than
    :data:`TELEPORT_M_S` between two frames: no body does; the source clip's own glitches, e.g.
    CMU subject 005's right knee swinging 30-45 cm about the hip-ankle line in one frame).
    """

    frames: int = 0
    correct: float = float("nan")
    wrong_frames: int = 0
    confident_wrong: float = float("nan")
    confident_wrong_marker: float = float("nan")
    bound_wrong: float = float("nan")
    unsure_joints: float = float("nan")
    solved: float = float("nan")
    reacquire_s: list[float] = field(default_factory=list)
    blackout_pose_s: float = 0.0
    mpjpe_m: float = float("nan")
    near_teleport: int = 0


def separable_visible(uv: np.ndarray, visible: np.ndarray, radius: np.ndarray, gap_px: float = 1.0) -> np.ndarray:
    """(F, 8) bool: markers seen apart from the others by >= 2 cameras.

    uv: (C, F, 8, 2) px; visible: (C, F, 8) bool; radius: (C, F, 8) px (truth2d.npz arrays)."""
    d = np.linalg.norm(uv[:, :, :, None, :] - uv[:, :, None, :, :], axis=-1)  # (C, F, 8, 8)
    touch = d <= radius[:, :, :, None] + radius[:, :, None, :] + gap_px
    touch &= visible[:, :, None, :] & visible[:, :, :, None]
    idx = np.arange(uv.shape[2])
    touch[:, :, idx, idx] = False
    apart = visible & ~touch.any(axis=3)
    return apart.sum(axis=0) >= 2


def teleports(truth: np.ndarray, fps: float) -> np.ndarray:
    """(F,) bool: frames whose true markers truth (F, 8, 3) m, one or more, moved faster than
    :data:`TELEPORT_M_S` since the frame before (the first frame: False)."""
    step = np.linalg.norm(np.diff(truth, axis=0), axis=2) * fps  # (F-1, 8) m/s
    return np.r_[False, (np.nan_to_num(step) > TELEPORT_M_S).any(axis=1)]


def score_take(markers: np.ndarray, joints: np.ndarray, truth_joints: np.ndarray, visible: np.ndarray,
               blackout: np.ndarray, fps: float, n_lead: int = 0, tol_m: float = 0.08,
               bounds: np.ndarray | None = None) -> TakeScore:
    """Score one take. markers: (F, 8, 3) named markers (NaN = not named); joints: (F, 13, 3)
    poses (NaN = none); truth_joints: (F, 13, 3); visible: (F, 8) from :func:`separable_visible`;
    blackout: (F,) bool; n_lead: frames of standard pose and lead-in before the motion;
    bounds: (F, 13) per-joint bounds (m) of the poses, or None."""
    truth = truth_joints[:, list(MARKER_JOINT)]
    named = np.isfinite(markers).all(axis=2)
    dd = np.linalg.norm(markers[:, :, None, :] - truth[:, None, :, :], axis=-1)  # (F, 8, 8)
    own = np.diagonal(dd, axis1=1, axis2=2)
    nearest = np.argmin(np.where(np.isfinite(dd), dd, np.inf), axis=2) == np.arange(8)
    right = named & ((own <= tol_m) | (nearest & (own <= 2.0 * tol_m)))
    wrong = named & ~right
    scored = ~blackout & visible.any(axis=1)
    ok = ~wrong.any(axis=1) & ~(visible & ~right).any(axis=1)
    solved = np.isfinite(joints).all(axis=(1, 2))
    err = np.linalg.norm(joints - truth_joints, axis=-1)
    s = TakeScore(frames=int(scored.sum()))
    if scored.any():
        s.correct = float(ok[scored].mean())
        s.wrong_frames = int((wrong.any(axis=1) & scored).sum())
        after = np.convolve(teleports(truth, fps), np.ones(max(int(round(TELEPORT_S * fps)), 1)))[:len(ok)] > 0
        s.near_teleport = int((~ok & scored & after).sum())
    outside = ~blackout
    s.solved = float(solved[outside].mean()) if outside.any() else float("nan")
    confident = solved & (named.sum(axis=1) >= 4)
    if confident.any():
        far = np.where(solved[:, None], err, 0.0) > 0.2
        s.confident_wrong = float(far.any(axis=1)[confident].mean())
        s.confident_wrong_marker = float(far[:, list(MARKER_JOINT)].any(axis=1)[confident].mean())
        if bounds is not None:
            sure = np.asarray(bounds, float) < CONFIDENT_M
            s.bound_wrong = float((far & sure).any(axis=1)[confident].mean())
            s.unsure_joints = float((~sure)[confident].mean())
    motion = solved.copy()
    motion[:n_lead] = False
    if motion.any():
        s.mpjpe_m = float(err[motion].mean())
    # blackouts: windows of consecutive True
    edges = np.flatnonzero(np.diff(np.r_[0, blackout.astype(int), 0]))
    for start, stop in zip(edges[::2], edges[1::2]):
        inside = np.flatnonzero(solved[start:stop])
        if inside.size:
            s.blackout_pose_s = max(s.blackout_pose_s, (inside.max() + 1) / fps)
        back = np.flatnonzero(right[stop:].sum(axis=1) >= 6)
        s.reacquire_s.append(float(back[0] / fps) if back.size else float("nan"))
    return s
