"""Pseudo-poses: database poses widened by small joint-angle noise (Samba thesis, section 4.2).

Works on the direction representation of :mod:`samba_common.body` (11 unit bone directions in
the torso frame). For each limb the root joint (shoulder, hip) is a two-DOF ball joint — a tilt
about the axis perpendicular to the bone and the shoulder line, then a turn about the bone's
original direction — that carries the lower bone along; the middle joint (elbow, knee) is a
hinge about the axis normal to the limb plane. The neck and the pelvis get the same two-DOF
noise, the spine a sideways lean about the torso's forward axis.
"""

from __future__ import annotations

import numpy as np

from samba_common.body import D, LIMBS

#: number of noise angles per pseudo-pose
N_ANGLES = 2 + 1 + 2 + 3 * len(LIMBS)

_X = np.array([1.0, 0.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of vectors v (..., 3) about unit axes (..., 3) by angles (...,) radians."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1.0 - c)


def _ball_axes(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For bone directions d (M, 3): the tilt axis R1 = Z x X (thesis eq. 4.10) and the bone axis Z."""
    x = _X - np.sum(d * _X, axis=-1, keepdims=True) * d
    bad = np.linalg.norm(x, axis=-1) < 1e-6  # bone along the shoulder line: use the forward axis
    x[bad] = (_Z - np.sum(d * _Z, axis=-1, keepdims=True) * d)[bad]
    x = _unit(x)
    return _unit(np.cross(d, x)), d


def _ball(vs: list[np.ndarray], d: np.ndarray, a1: np.ndarray, a2: np.ndarray) -> list[np.ndarray]:
    r1, z = _ball_axes(d)
    return [rotate(rotate(v, r1, a1), z, a2) for v in vs]


def pseudo_poses(dirs: np.ndarray, noise: np.ndarray, ball_sigma: float, hinge_sigma: float) -> np.ndarray:
    """Widen K poses into K*(N+1) poses: each original followed by N pseudo-poses.

    dirs: (K, 11, 3) unit bone directions; noise: (N, N_ANGLES) standard normal numbers (a fixed
    bank keeps the result deterministic); ball_sigma / hinge_sigma: radians.
    Returns (K * (N + 1), 11, 3).
    """
    K, N = dirs.shape[0], noise.shape[0]
    if N == 0:
        return dirs.copy()
    out = np.repeat(dirs[:, None], N + 1, axis=1)  # (K, N+1, 11, 3)
    p = out[:, 1:].reshape(K * N, 11, 3).copy()
    sigma = np.full(N_ANGLES, ball_sigma)
    sigma[7::3] = hinge_sigma  # the third angle of each limb is its hinge
    ang = np.tile(noise * sigma, (K, 1))  # (K*N, N_ANGLES) radians
    col = 5
    nd = D["neck"]
    p[:, nd] = _ball([p[:, nd]], p[:, nd], ang[:, 0], ang[:, 1])[0]
    sd = D["spine"]
    p[:, sd] = rotate(p[:, sd], np.broadcast_to(_Z, p[:, sd].shape), ang[:, 2])
    pd = D["pelvis"]
    # the pelvis line turns about the spine and tilts about the forward axis
    p[:, pd] = rotate(rotate(p[:, pd], _unit(p[:, sd]), ang[:, 3]), np.broadcast_to(_Z, p[:, pd].shape), ang[:, 4])
    for _side, upper, lower, *_ in LIMBS:
        u, lo = D[upper], D[lower]
        a1, a2, ah = ang[:, col], ang[:, col + 1], ang[:, col + 2]
        col += 3
        hinge = np.cross(p[:, u], p[:, lo])
        straight = np.linalg.norm(hinge, axis=-1) < 1e-3
        hinge[straight] = _ball_axes(p[straight, u])[0]
        hinge = _unit(hinge)
        lower_bent = rotate(p[:, lo], hinge, ah)
        p[:, u], p[:, lo] = _ball([p[:, u], lower_bent], p[:, u], a1, a2)
    out[:, 1:] = p.reshape(K, N, 11, 3)
    return out.reshape(K * (N + 1), 11, 3)
