"""Per-joint error bounds of a solved pose: how far each joint may be from where it is drawn.

Eight markers pin the shoulders, wrists, knees and ankles; the other five joints are the
motion database's guess. An elbow can turn about the line from its shoulder to its wrist on a
circle whose radius grows as the arm bends; the hips can swing about the shoulders while both
thighs still reach their knees; the head follows the spine. How well the database guesses
depends on whether it holds bodies like this one: the distance from the frame's trunk and
leg markers to the nearest database pose (its "novelty") says so.

A joint's bound (metres) is a size its error stays under in about 95 % of frames, measured with
the true markers on held-out subjects (each clip solved with a database without its subject;
docs/reconstruction.md, "Per-joint bounds"):

- marker joints: ``MARKER_BOUND`` plus three times the solved marker's distance from the
  observed one; a marker not observed this frame: the bound it had when last observed, plus
  ``UNSEEN_SPEED`` per second since (how far the marker may have gone), plus how far the solve
  has put it from where it was last observed (the triangle inequality: the solver may move an
  unseen limb anywhere); inf if never observed in this solve;
- elbows: the swivel circle's radius r times ``ELBOW_SWIVEL`` (+ half the novelty, counted up to
  ``NOVELTY_CAP``), at least the bound of its shoulder and wrist;
- hips: ``HIP_BASE`` + ``HIP_NOVELTY`` * novelty, at least the bound of its knee and of the shoulders;
- head: ``HEAD_BASE`` + ``HEAD_NOVELTY`` * novelty, at least the shoulders' bound.

A joint is *confident* when its bound is below :data:`CONFIDENT_M` (20 cm, issue 12's "wrong"):
what a user may take as measured. The rest is drawn, but is a guess.
"""

from __future__ import annotations

import numpy as np

from samba_common.skeleton import BONE_TYPES, JOINT_NAMES, MARKER_JOINT, N_JOINTS, N_MARKERS

#: a joint whose bound is below this (metres) is confident
CONFIDENT_M = 0.2
#: bound of a joint whose marker was observed and fitted exactly (m)
MARKER_BOUND = 0.02
#: how fast an unobserved marker's joint may have moved away from its prediction (m/s)
UNSEEN_SPEED = 2.0
#: elbow bound = swivel radius * (ELBOW_SWIVEL + min(novelty, NOVELTY_CAP) / 2)
ELBOW_SWIVEL = 1.15
NOVELTY_CAP = 0.4
#: hip bound = HIP_BASE + HIP_NOVELTY * novelty (m)
HIP_BASE = 0.05
HIP_NOVELTY = 0.5
#: head bound = HEAD_BASE + HEAD_NOVELTY * novelty (m)
HEAD_BASE = 0.03
HEAD_NOVELTY = 0.25

_J = {n: i for i, n in enumerate(JOINT_NAMES)}
#: (elbow, shoulder, wrist) joint indices per arm
_ARMS = ((_J["left_elbow"], _J["left_shoulder"], _J["left_wrist"]),
         (_J["right_elbow"], _J["right_shoulder"], _J["right_wrist"]))
_SHOULDERS = [_J["left_shoulder"], _J["right_shoulder"]]
_KNEES = [_J["left_knee"], _J["right_knee"]]
_ANKLES = [_J["left_ankle"], _J["right_ankle"]]
_WRISTS = [_J["left_wrist"], _J["right_wrist"]]
_HIPS = [_J["left_hip"], _J["right_hip"]]
_HEAD = _J["head"]
_UPPER_ARM, _FOREARM = BONE_TYPES.index("upper_arm"), BONE_TYPES.index("forearm")  # into the lengths (8,)


def swivel_radius(shoulder: np.ndarray, wrist: np.ndarray, upper_arm: float, forearm: float) -> float:
    """Radius (m) of the circle an elbow may lie on, given its shoulder and wrist joints (3,)
    metres and the arm's bone lengths (m): 0 for a straight (or over-stretched) arm."""
    d = float(np.linalg.norm(wrist - shoulder))
    if not np.isfinite(d) or d <= 1e-9:
        return float(upper_arm) if np.isfinite(d) else float("nan")
    a = (upper_arm ** 2 - forearm ** 2 + d * d) / (2.0 * d)
    return float(np.sqrt(max(upper_arm ** 2 - a * a, 0.0)))


def joint_bounds(joints: np.ndarray, at_markers: np.ndarray, novelty: float, lengths: np.ndarray) -> np.ndarray:
    """Bounds (13,) metres of solved joints (13, 3) world metres, from the bounds at_markers (8,)
    of the marker joints (see :func:`marker_bounds`), the frame's novelty (m; NaN counts as
    ``NOVELTY_CAP`` for the elbows and as 1 m for hips and head) and the subject's bone lengths
    (8,) m. NaN joints get inf."""
    if not np.isfinite(joints).all():
        return np.full(N_JOINTS, np.inf)
    nov = float(novelty) if np.isfinite(novelty) else 1.0
    out = np.zeros(N_JOINTS)
    for elbow, sh, wr in _ARMS:
        r = swivel_radius(joints[sh], joints[wr], float(lengths[_UPPER_ARM]), float(lengths[_FOREARM]))
        out[elbow] = r * (ELBOW_SWIVEL + 0.5 * min(nov, NOVELTY_CAP))
    out[_HIPS] = HIP_BASE + HIP_NOVELTY * nov
    out[_HEAD] = HEAD_BASE + HEAD_NOVELTY * nov
    return widened(out, at_markers)


def widened(bounds: np.ndarray, at_markers: np.ndarray) -> np.ndarray:
    """Bounds (..., 13) m with each marker joint's raised to at least at_markers (..., 8) m and
    the joints placed from it raised with it: an elbow to its shoulder's and wrist's, the hips
    to the shoulders' and their knee's, the head to the shoulders'. A new array."""
    out = np.array(bounds, float)
    for i, j in enumerate(MARKER_JOINT):
        out[..., j] = np.maximum(out[..., j], at_markers[..., i])
    for elbow, sh, wr in _ARMS:
        out[..., elbow] = np.maximum(out[..., elbow], np.maximum(out[..., sh], out[..., wr]))
    shoulders = out[..., _SHOULDERS].max(axis=-1)
    for hip, knee in zip(_HIPS, _KNEES):
        out[..., hip] = np.maximum(out[..., hip], np.maximum(shoulders, out[..., knee]))
    out[..., _HEAD] = np.maximum(out[..., _HEAD], shoulders)
    return out


def mirrored_legs(bounds: np.ndarray, joints: np.ndarray, unsure: np.ndarray | bool) -> np.ndarray:
    """Bounds (..., 13) m with, where unsure (...) bool (the legs' names may be each other's:
    :attr:`samba_server.labelling.Labeller.legs_unsure`), each knee's and ankle's raised to
    its distance from the other side's, joints (..., 13, 3) m: named the other way round, the
    joint would be there. The hips stay (mirrored legs move them by a few cm). A new array."""
    return _mirrored(bounds, joints, unsure, ((_KNEES, _KNEES), (_ANKLES, _ANKLES)))


def mirrored_wrists(bounds: np.ndarray, joints: np.ndarray, unsure: np.ndarray | bool) -> np.ndarray:
    """Bounds (..., 13) m with, where unsure (...) bool (the wrists' names may be each other's:
    no view saw them apart, :meth:`samba_server.labelling.Labeller.unseparated`), each wrist's
    and elbow's raised to the distance between the wrists of joints (..., 13, 3) m. A new array."""
    return _mirrored(bounds, joints, unsure, ((_WRISTS, _WRISTS + [elbow for elbow, _sh, _wr in _ARMS]),))


def mirrored_pairs(bounds: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Bounds (..., 13) m with every left/right pair of arm and leg joints' raised to their
    distance apart in joints (..., 13, 3) m, the elbows' also to the shoulders' and wrists': what
    fewer than 3 cameras give. Every pair of blobs on an epipolar line is then a 3D point and
    a naming and its mirror image fit bodies alike; on the labelling benchmark with 2 cameras
    two thirds of the confidently wrong joints were a left one drawn where the right one is (or
    the other way round), and no per-frame figure (solver residual, identification margin,
    the passes' agreement) told those frames apart. Each raise also adds the larger of the
    pair's own bounds: named the other way round, a joint is where the other side's is drawn
    only as surely as that one is (a knee named on the other knee's point while that one is
    hidden was drawn 33-50 cm off with a 9-16 cm bound). The hips and the head then take the
    raised bounds of the markers they are placed from (:func:`widened`): names a pair of views
    cannot tell apart are not only mirrored but shifted (a shoulder on the other one, that one on
    a wrist), which moves the head and hips with them (drawn 22-44 cm off with 11-20 cm bounds).
    A new array."""
    elbows = [elbow for elbow, _sh, _wr in _ARMS]
    out = _mirrored(bounds, joints, True, ((_SHOULDERS, _SHOULDERS + elbows), (_WRISTS, _WRISTS + elbows),
                                           (elbows, elbows), (_KNEES, _KNEES), (_ANKLES, _ANKLES)), own=True)
    return widened(out, out[..., list(MARKER_JOINT)])


def _mirrored(bounds: np.ndarray, joints: np.ndarray, unsure: np.ndarray | bool, groups,
              own: bool = False) -> np.ndarray:
    """Bounds (..., 13) m with, where unsure (...), the joints of each group raised to the
    distance apart in joints (..., 13, 3) m of its (left, right) pair (own: plus the larger of
    the pair's bounds as given). groups: ((left, right), joints raised) pairs. A new array."""
    given = np.asarray(bounds, float)
    out = given.copy()
    unsure = np.asarray(unsure, bool)
    joints = np.asarray(joints, float)
    for (left, right), raised in groups:
        apart = np.linalg.norm(joints[..., left, :] - joints[..., right, :], axis=-1)
        apart = np.where(unsure & np.isfinite(apart), apart, 0.0)
        if own:
            apart = np.where(apart > 0.0, apart + np.maximum(given[..., left], given[..., right]), 0.0)
        for j in raised:
            out[..., j] = np.maximum(out[..., j], apart)
    return out


def marker_bounds(observed: np.ndarray, model: np.ndarray, state: tuple[np.ndarray, np.ndarray, np.ndarray],
                  t: float) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Bounds (8,) m of the marker joints of one solved frame at t s: observed (8, 3) markers
    (NaN rows unobserved), the solve's model markers (8, 3), and the state of the markers'
    last observations (:func:`fresh_marker_state`). Returns (bounds, the state updated for the
    observed markers)."""
    last, t_last, pos = state
    seen = np.isfinite(observed).all(axis=1)
    fit = np.linalg.norm(model - observed, axis=1)
    last, t_last, pos = last.copy(), t_last.copy(), pos.copy()
    last[seen] = MARKER_BOUND + 3.0 * np.where(np.isfinite(fit[seen]), fit[seen], np.inf)
    t_last[seen] = t
    pos[seen] = observed[seen]
    out = last.copy()
    gap = np.where(np.isfinite(t_last), abs(t - t_last), np.inf)
    moved = np.linalg.norm(model - pos, axis=1)
    out[~seen] = last[~seen] + UNSEEN_SPEED * gap[~seen] + np.where(np.isfinite(moved[~seen]), moved[~seen], np.inf)
    return out, (last, t_last, pos)


def fresh_marker_state() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The markers' last observations before any frame (never observed): their bounds (8,) m,
    times (8,) s and positions (8, 3) m."""
    return np.full(N_MARKERS, np.inf), np.full(N_MARKERS, np.nan), np.full((N_MARKERS, 3), np.nan)


def guessed_summary(bounds: np.ndarray, solved: np.ndarray) -> str:
    """One line for a take's summary: the share of confident joints in the solved frames and
    the joints most often guessed. bounds: (F, 13) m; solved: (F,) bool."""
    b = np.asarray(bounds, float)[np.asarray(solved, bool)]
    if len(b) == 0:
        return "joint bounds: no solved frame"
    guessed = ~(b < CONFIDENT_M)  # (n, 13)
    share = guessed.mean(axis=0)
    worst = [f"{JOINT_NAMES[j].replace('_', ' ')} {100 * share[j]:.0f} %" for j in np.argsort(-share)[:3]
             if share[j] >= 0.005]
    line = f"joints confident (bound < {100 * CONFIDENT_M:.0f} cm): {100 * (1 - guessed.mean()):.1f} % of solved joints"
    return line + (f"; most often guessed: {', '.join(worst)}" if worst else "")

