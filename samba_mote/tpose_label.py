"""T-pose labelling of the 8 markers in one camera image (the standard pose, FORMATS.md).

The 8 markers of a T-pose lie almost in one plane (the body's frontal plane), so their image
is an affine image of a planar template. Blobs are grouped by height (4 upper = shoulders +
wrists, then knees, then ankles), the outer upper pair are wrists, and left/right follows from
the view: seen from the front the subject's right is on the image left. The affine invariants
of a T-pose (wrists and shoulders collinear, arm span 2.5-7 x shoulder width) and the affine
residual decide; with more than 8 blobs (clutter) every 8-subset is tried.
"""

from __future__ import annotations

import itertools

import numpy as np

from samba_common.skeleton import N_MARKERS

# marker indices (MARKER_NAMES order)
L_SH, R_SH, L_WR, R_WR, L_KN, R_KN, L_AN, R_AN = range(8)

#: planar T-pose template, (8, 2): x toward the subject's right (m), z up (m)
TPOSE_TEMPLATE = np.array([
    [-0.18, 1.45], [0.18, 1.45],  # shoulders
    [-0.72, 1.45], [0.72, 1.45],  # wrists
    [-0.16, 0.50], [0.16, 0.50],  # knees (feet apart, see samba_mote.sim.tpose)
    [-0.22, 0.08], [0.22, 0.08],  # ankles
])


def view_from_calibration(camera) -> str | None:
    """"front" if the subject's right (+X) appears on the image left for a subject at the origin,
    "back" if on the right, None for a side view (|du| < 5 px per metre)."""
    p = camera.project(np.array([[0.0, 0.0, 1.2], [0.5, 0.0, 1.2]]))
    du = (p[1, 0] - p[0, 0]) / 0.5
    if not np.isfinite(du) or abs(du) < 5.0:
        return None
    return "front" if du < 0 else "back"


def _assign_layout(uv: np.ndarray, right_is_left: bool) -> np.ndarray:
    """uv (8, 2) blobs of a T-pose -> (8,) blob index per marker (MARKER_NAMES order)."""
    by_v = np.argsort(uv[:, 1], kind="stable")
    upper, knees, ankles = by_v[:4], by_v[4:6], by_v[6:8]
    upper = upper[np.argsort(uv[upper, 0], kind="stable")]
    out = np.empty(8, np.int64)

    def lr(pair):  # (left marker blob, right marker blob)
        a, b = pair if uv[pair[0], 0] <= uv[pair[1], 0] else pair[::-1]
        return (b, a) if right_is_left else (a, b)

    out[L_WR], out[R_WR] = lr(np.array([upper[0], upper[3]]))
    out[L_SH], out[R_SH] = lr(np.array([upper[1], upper[2]]))
    out[L_KN], out[R_KN] = lr(knees)
    out[L_AN], out[R_AN] = lr(ankles)
    return out


def _affine_residual(src: np.ndarray, dst: np.ndarray) -> float:
    """RMS residual of the best affine map src (8, 2) -> dst (8, 2), divided by dst's height span."""
    A = np.hstack([src, np.ones((len(src), 1))])
    coef, *_ = np.linalg.lstsq(A, dst, rcond=None)
    res = A @ coef - dst
    span = max(float(np.ptp(dst[:, 1])), 1e-6)
    return float(np.sqrt((res ** 2).sum(1).mean()) / span)


def label_tpose(uv: np.ndarray, view: str = "front", tolerance: float = 0.06,
                max_blobs: int = 11) -> tuple[np.ndarray, float] | None:
    """Find a T-pose among blobs uv (N, 2) px.

    Returns (index (8,) into uv per marker, normalised residual) or None when no subset of 8
    blobs fits the template within ``tolerance`` (or N < 8 or N > max_blobs).
    """
    n = len(uv)
    if n < N_MARKERS or n > max_blobs:
        return None
    right_is_left = view == "front"
    best: tuple[np.ndarray, float] | None = None
    for subset in itertools.combinations(range(n), N_MARKERS):
        sub = np.asarray(subset)
        idx = sub[_assign_layout(uv[sub], right_is_left)]
        pts = uv[idx]
        # sanity: wrists outside shoulders, knees below the upper group, ankles below knees
        if not (pts[[L_KN, R_KN], 1].min() > pts[:4, 1].max() and pts[[L_AN, R_AN], 1].min() > pts[[L_KN, R_KN], 1].max()):
            continue
        # affine invariants of a T-pose: wrists and shoulders on one line, arm span ~4x shoulders
        span = np.linalg.norm(pts[L_WR] - pts[R_WR])
        ratio = span / max(float(np.linalg.norm(pts[L_SH] - pts[R_SH])), 1e-6)
        if not 2.5 <= ratio <= 7.0:
            continue
        axis = (pts[L_WR] - pts[R_WR]) / max(span, 1e-6)
        normal = np.array([-axis[1], axis[0]])
        off = (pts[:4] - pts[R_WR]) @ normal
        if np.abs(off).max() > 0.12 * span:
            continue
        r = _affine_residual(TPOSE_TEMPLATE, pts)
        if r <= tolerance and (best is None or r < best[1]):
            best = (idx, r)
    return best
