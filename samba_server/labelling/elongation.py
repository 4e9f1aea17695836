"""Two markers in one blob: their separation from the blob's elongation.

Two equal markers a vector s (px) apart blur into one blob whose second central moments are a
single marker's plus s s^T / 4. The gap between the two eigenvalues of the blob's 2x2
covariance is therefore |s|^2 / 4, along the major axis: the mote measures the separation of
two markers it cannot see apart, up to its sign (on rendered takes to 0.05 px median for
markers 3-6 px apart; a single marker's own shape reads as 0.5 px median, so below ~1 px the
measure only says "nearly in line with the ray").

A 3D point seen as a merged blob in several views is the midpoint of two markers; each view's
separation is the projection of their 3D separation S (m) through that camera's Jacobian at
the point, up to a sign per view. :func:`separation_3d` finds S by least squares over the
views' sign combinations, with a prior (the guess the labeller would make without the
moments: along the subject's right, or the markers' predicted difference) that fills what the
views do not see (a single view says nothing along its ray) and fixes the overall sign.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["blob_separation", "jacobians", "separation_3d"]


def blob_separation(moments: np.ndarray) -> np.ndarray:
    """(N, 2) px separation vector of two equal markers in each blob (sign arbitrary; NaN where
    the moments are unknown). moments: (N, 3) (var_u, cov_uv, var_v) px^2."""
    m = np.asarray(moments, float).reshape(-1, 3)
    vu, cuv, vv = m[:, 0], m[:, 1], m[:, 2]
    gap = np.sqrt((vu - vv) ** 2 + 4.0 * cuv ** 2)
    theta = 0.5 * np.arctan2(2.0 * cuv, vu - vv)
    d = 2.0 * np.sqrt(gap)
    return d[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def jacobians(project, X: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """(C, 2, 3) px/m derivative of every camera's projection at X (3,) m, by central
    differences (distortion included: the moments are in raw pixels). project: world points
    (N, 3) -> (C, N, 2) px, e.g. :meth:`~samba_server.triangulate.Triangulator.project`'s first
    result."""
    steps = h * np.eye(3)
    uv = project(np.concatenate([X + steps, X - steps]))  # (C, 6, 2)
    return ((uv[:, :3] - uv[:, 3:]) / (2.0 * h)).transpose(0, 2, 1)


def separation_3d(J: np.ndarray, seps: np.ndarray, prior: np.ndarray, sigma_px: float = 0.5,
                  prior_m: float = 0.1, max_m: float = 0.35) -> np.ndarray | None:
    """3D separation S (3,) m of two markers at one point from the separation vectors seps
    (V, 2) px (sign arbitrary) that V views measured, J (V, 2, 3) px/m those views'
    projection Jacobians at the point (:func:`jacobians`), and a prior (3,) m with a standard
    deviation of prior_m per axis (its sign chooses S's sign). sigma_px: the measure's standard
    deviation. None when no view measured (or the result is longer than max_m, which no merged
    blob holds)."""
    J = np.asarray(J, float).reshape(-1, 2, 3)
    seps = np.asarray(seps, float).reshape(-1, 2)
    good = np.isfinite(seps).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
    J, seps = J[good], seps[good]
    V = len(seps)
    if V == 0:
        return None
    prior = np.asarray(prior, float)
    A = np.concatenate([J.reshape(2 * V, 3) / sigma_px, np.eye(3) / prior_m])  # (2V + 3, 3)
    # a view's sign is unknown: every combination at once, (2V + 3, 2^V) right-hand sides
    signs = np.array(list(itertools.product((1.0, -1.0), repeat=V))).T  # (V, 2^V)
    B = np.concatenate([(seps[:, :, None] * signs[:, None, :]).reshape(2 * V, -1) / sigma_px,
                        np.repeat(prior[:, None] / prior_m, signs.shape[1], axis=1)])
    S = np.linalg.lstsq(A, B, rcond=None)[0]  # (3, 2^V)
    best = S[:, int(np.argmin(np.sum((A @ S - B) ** 2, axis=0)))]
    if not np.isfinite(best).all() or float(np.linalg.norm(best)) > max_m:
        return None
    return best
