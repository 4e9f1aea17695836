"""Body-frame alignment of marker and joint sets, and its inverse.

The body frame (after the Samba thesis, with a robust "up" axis):

- origin: the shoulder midpoint;
- x: from the right shoulder to the left shoulder;
- y: "up the body": the direction from the feet to the shoulders, made orthogonal to x. The
  thesis takes it from the right wrist, which degenerates whenever the arm lies along the
  shoulder line (a T-pose!). We take the ankle midpoint, falling back to the knee midpoint,
  then to world +Z, then to world +Y, whichever first has a component orthogonal to x of at
  least ``min_perp`` of its length;
- z = x × y (right-handed; the thesis' y × x gives a mirrored frame), pointing forward;
- scale: the lower leg (knee–ankle, mean of both sides) has length 1, unless a scale is given.

Points are (..., P, 3). ``align`` returns aligned points plus the :class:`Frame` that maps them
back with ``unalign``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skeleton import M

_WORLD_FALLBACKS = (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))


class AlignmentError(ValueError):
    """The points do not determine a body frame (a shoulder missing, shoulders coincide)."""


@dataclass(frozen=True)
class Frame:
    """A body frame: ``aligned = (world - origin) @ R / scale``; ``world = origin + scale * aligned @ R.T``.

    origin: (3,) metres; R: (3, 3) columns are the body x, y, z axes in world coordinates;
    scale: metres per aligned unit.
    """

    origin: np.ndarray
    R: np.ndarray
    scale: float


def body_frame(l_sh: np.ndarray, r_sh: np.ndarray, downs: list[np.ndarray], scale: float = 1.0,
               min_perp: float = 0.2) -> Frame:
    """Frame from the two shoulders (3,) and candidate points below the torso, in order of preference.

    downs: points such as the ankle midpoint, knee midpoint; NaN entries are skipped.
    Raises AlignmentError when a shoulder is NaN or the shoulders coincide.
    """
    if not (np.all(np.isfinite(l_sh)) and np.all(np.isfinite(r_sh))):
        raise AlignmentError("both shoulders are needed for the body frame")
    x = l_sh - r_sh
    n = np.linalg.norm(x)
    if n < 1e-9:
        raise AlignmentError("the shoulders coincide")
    x = x / n
    origin = 0.5 * (l_sh + r_sh)
    ups = [origin - d for d in downs if np.all(np.isfinite(d))] + list(_WORLD_FALLBACKS)
    for u in ups:
        un = np.linalg.norm(u)
        if un < 1e-9:
            continue
        perp = u - (u @ x) * x
        pn = np.linalg.norm(perp)
        if pn >= min_perp * un:
            y = perp / pn
            break
    else:  # x is along both world fallbacks at once: impossible, kept for safety
        raise AlignmentError("no up direction")
    z = np.cross(x, y)
    return Frame(origin, np.stack([x, y, z], axis=1), float(scale))


def _mid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 0.5 * (a + b)


def marker_frame(markers: np.ndarray, scale: float | None = None) -> Frame:
    """Body frame of one set of 8 markers (8, 3) (MARKER_NAMES order, NaN = missing).

    scale: metres per unit; None = the mean shin length measured from the markers
    (AlignmentError if no shin is visible).
    """
    if scale is None:
        shins = [np.linalg.norm(markers[M[f"{s}_knee"]] - markers[M[f"{s}_ankle"]]) for s in ("left", "right")]
        shins = [v for v in shins if np.isfinite(v) and v > 1e-6]
        if not shins:
            raise AlignmentError("no knee-ankle pair visible to set the scale")
        scale = float(np.mean(shins))
    downs = [_mid(markers[M["left_ankle"]], markers[M["right_ankle"]]),
             _mid(markers[M["left_knee"]], markers[M["right_knee"]])]
    return body_frame(markers[M["left_shoulder"]], markers[M["right_shoulder"]], downs, scale)


def align(points: np.ndarray, frame: Frame) -> np.ndarray:
    """World points (..., 3) metres -> body-frame points (..., 3) in frame units."""
    return (points - frame.origin) @ frame.R / frame.scale


def unalign(points: np.ndarray, frame: Frame) -> np.ndarray:
    """Body-frame points (..., 3) -> world points (..., 3) metres (inverse of :func:`align`)."""
    return frame.origin + frame.scale * points @ frame.R.T


def batch_frames(markers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`marker_frame` for complete sets (F, 8, 3) -> origin (F, 3), R (F, 3, 3).

    Frames whose ankle/knee up-vector degenerates use the world fallbacks as
    :func:`body_frame` does. Rows with NaN produce NaN.
    """
    ls, rs = markers[:, M["left_shoulder"]], markers[:, M["right_shoulder"]]
    origin = 0.5 * (ls + rs)
    x = ls - rs
    x = x / np.linalg.norm(x, axis=1, keepdims=True)
    cands = [origin - _mid(markers[:, M["left_ankle"]], markers[:, M["right_ankle"]]),
             origin - _mid(markers[:, M["left_knee"]], markers[:, M["right_knee"]])]
    cands += [np.broadcast_to(w, origin.shape) for w in _WORLD_FALLBACKS]
    y = np.full_like(origin, np.nan)
    todo = np.ones(len(origin), bool)
    for u in cands:
        perp = u - np.sum(u * x, axis=1, keepdims=True) * x
        pn = np.linalg.norm(perp, axis=1)
        ok = todo & (pn >= 0.2 * np.linalg.norm(u, axis=1)) & (pn > 1e-9)
        y[ok] = perp[ok] / pn[ok, None]
        todo &= ~ok
    z = np.cross(x, y)
    return origin, np.stack([x, y, z], axis=2)


def align_batch(markers: np.ndarray, points: np.ndarray | None = None, scale: float | np.ndarray = 1.0) -> np.ndarray:
    """Align ``points`` (F, P, 3) (default: the markers) in the frames of ``markers`` (F, 8, 3).

    scale: metres per unit, scalar or (F,). Returns (F, P, 3).
    """
    origin, R = batch_frames(markers)
    pts = markers if points is None else points
    rel = pts - origin[:, None, :]
    return np.einsum("fpi,fij->fpj", rel, R) / np.reshape(scale, (-1, 1, 1))
