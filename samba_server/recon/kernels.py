"""Compiled (numba) kernels of the per-frame solve: pseudo-poses, local prior, linear start, LM.

Array conventions follow :mod:`samba_common.body`: bone directions (11, 3) in the torso frame,
``BONE_DIRS`` order; bone lengths (8,), ``BONE_TYPES`` order; joints (13, 3), ``JOINT_NAMES``
order; torso rotation ``R`` (3, 3) with the torso axes as columns; metres.

The energy minimised by :func:`lm_solve` is

    |W (v(state) - mu)|^2 + sum_seen |(q_m - x_m) / sigma_m[m]|^2 + [smooth] sum_j |(q_j - target_j) / sigma_s|^2

where v is the 42-vector (vec(dirs), torso y and z axes in the marker body frame ``RA``, world
up in torso coordinates), q the
world joints, sigma_m (8,) each marker's noise (m) and target the constant-velocity prediction
(second difference of the pose).
The tangent step has 27 entries: rotation vector (3), translation (3), then two tangent angles
per bone except the spine, which only leans in the torso's x-y plane (see :func:`param_col`).

Everything here is compiled once (``cache=True`` stores the machine code next to the module).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: fast-math flags for the compiled kernels: reassociation lets reductions vectorise; no
#: "nnan"/"ninf", which would make NaN tests (missing markers) always false
FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}

from .kdtree import knn

N_POSE = 42
N_ANGLES = 17  # neck 2, spine 1, pelvis 2, 4 limbs x (ball 2 + hinge 1)

# bone directions
NECK, PELVIS, SPINE, LUA, RUA, LFA, RFA, LTH, RTH, LSH, RSH = range(11)
# joints
HEAD, LS, RS, LE, RE, LW, RW, LH, RH, LK, RK, LA, RA = range(13)
MARKER_JOINTS = np.array([LS, RS, LW, RW, LK, RK, LA, RA])
# bone type of each direction (index into the 8 lengths)
BONE_LENGTH = np.array([3, 1, 2, 4, 4, 5, 5, 6, 6, 7, 7])
# limbs: (upper bone, lower bone)
LIMB_BONES = np.array([[LUA, LFA], [RUA, RFA], [LTH, LSH], [RTH, RSH]])


def incidence() -> np.ndarray:
    """G (13, 12): body joints = G @ [half shoulder line; L_b d_b for the 11 bones]."""
    G = np.zeros((13, 12))
    G[LS, 0], G[RS, 0], G[HEAD, 1 + NECK] = 1.0, -1.0, 1.0
    G[LH, 1 + SPINE] = G[RH, 1 + SPINE] = 1.0
    G[LH, 1 + PELVIS], G[RH, 1 + PELVIS] = 0.5, -0.5
    for a, b, c, up, lo in ((LS, LE, LW, LUA, LFA), (RS, RE, RW, RUA, RFA), (LH, LK, LA, LTH, LSH), (RH, RK, RA, RTH, RSH)):
        G[b] = G[a]
        G[b, 1 + up] = 1.0
        G[c] = G[b]
        G[c, 1 + lo] = 1.0
    return G


G = incidence()


@njit(cache=True, fastmath=FAST)
def param_col(b: int, k: int) -> int:
    """Column of tangent angle k (0/1) of bone b in the 27-parameter step (-1: not a parameter)."""
    if b < SPINE:
        return 6 + 2 * b + k
    if b == SPINE:
        return 10 if k == 0 else -1
    return 6 + 2 * b + k - 1


@njit(cache=True, fastmath=FAST)
def _normalize(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n < 1e-12:
        return v.copy()
    return v / n


@njit(cache=True, fastmath=FAST)
def _rot3cs(v0, v1, v2, a0, a1, a2, c, s):
    """Rodrigues rotation of (v0, v1, v2) about the unit axis (a0, a1, a2), given cos and sin."""
    d = (a0 * v0 + a1 * v1 + a2 * v2) * (1.0 - c)
    return (v0 * c + (a1 * v2 - a2 * v1) * s + a0 * d,
            v1 * c + (a2 * v0 - a0 * v2) * s + a1 * d,
            v2 * c + (a0 * v1 - a1 * v0) * s + a2 * d)


@njit(cache=True, fastmath=FAST)
def _unit3(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-12:
        return x, y, z
    return x / n, y / n, z / n


@njit(cache=True, fastmath=FAST)
def _ball_axis(d0, d1, d2):
    """Tilt axis of a ball joint (thesis eq. 4.10: R1 = Z x X, X = shoulder line made orthogonal
    to the bone Z); the forward axis stands in when the bone lies along the shoulder line."""
    x0, x1, x2 = 1.0 - d0 * d0, -d0 * d1, -d0 * d2
    if x0 * x0 + x1 * x1 + x2 * x2 < 1e-12:
        x0, x1, x2 = -d2 * d0, -d2 * d1, 1.0 - d2 * d2
    x0, x1, x2 = _unit3(x0, x1, x2)
    return _unit3(d1 * x2 - d2 * x1, d2 * x0 - d0 * x2, d0 * x1 - d1 * x0)


@njit(cache=True, fastmath=FAST)
def _ball(d, b, c1, s1, c2, s2):
    """Rotate bone b of d (11, 3) by a tilt (cos c1, sin s1) about its ball axis, then a turn
    (c2, s2) about the bone."""
    z0, z1, z2 = d[b, 0], d[b, 1], d[b, 2]
    r0, r1, r2 = _ball_axis(z0, z1, z2)
    v0, v1, v2 = _rot3cs(z0, z1, z2, r0, r1, r2, c1, s1)
    d[b, 0], d[b, 1], d[b, 2] = _rot3cs(v0, v1, v2, z0, z1, z2, c2, s2)


@njit(cache=True, fastmath=FAST)
def _trunk_noise(d, c, s):
    """Neck ball, spine lean and pelvis turn/tilt noise on directions d (11, 3), in place;
    c, s: (17,) cosines and sines of the noise angles."""
    _ball(d, NECK, c[0], s[0], c[1], s[1])
    d[SPINE, 0], d[SPINE, 1], d[SPINE, 2] = _rot3cs(d[SPINE, 0], d[SPINE, 1], d[SPINE, 2], 0.0, 0.0, 1.0, c[2], s[2])
    s0, s1, s2 = _unit3(d[SPINE, 0], d[SPINE, 1], d[SPINE, 2])
    v0, v1, v2 = _rot3cs(d[PELVIS, 0], d[PELVIS, 1], d[PELVIS, 2], s0, s1, s2, c[3], s[3])
    d[PELVIS, 0], d[PELVIS, 1], d[PELVIS, 2] = _rot3cs(v0, v1, v2, 0.0, 0.0, 1.0, c[4], s[4])


@njit(cache=True, fastmath=FAST)
def _in_limbs(b, limb_lo, limb_hi):
    for limb in range(limb_lo, limb_hi):
        if LIMB_BONES[limb, 0] == b or LIMB_BONES[limb, 1] == b:
            return True
    return False


@njit(cache=True, fastmath=FAST)
def pseudo_pool(db_dirs, nbr, cos_a, sin_a, out, trunk=True, limb_lo=0, limb_hi=4, only_limbs=False):
    """Fill out (K*(N+1), 11, 3) with each neighbour's directions followed by N pseudo-poses.

    db_dirs: (M, 11, 3) float32 database; nbr: (K,) indices; cos_a, sin_a: (N, 17) cosines and
    sines of the noise angles (a fixed bank, so the result is deterministic). Limb roots are 2-DOF
    balls carrying the lower bone; elbows and knees are hinges about the limb-plane normal; neck
    and pelvis are balls, the spine leans about the torso's forward axis, the pelvis also turns
    about the spine. Only the trunk (neck, spine, pelvis) when ``trunk`` and limbs
    limb_lo..limb_hi-1 (0 left arm, 1 right arm, 2 left leg, 3 right leg) are perturbed: a body
    part's prior needs only its own bones. With ``only_limbs`` only those limbs' bones are written
    (the other entries of ``out`` are left as they were).
    """
    K, N = nbr.shape[0], cos_a.shape[0]
    p = 0
    for i in range(K):
        for b in range(11):
            if only_limbs and not _in_limbs(b, limb_lo, limb_hi):
                continue
            for c in range(3):
                out[p, b, c] = db_dirs[nbr[i], b, c]
        base = p
        p += 1
        for n in range(N):
            d = out[p]
            if only_limbs:
                for limb in range(limb_lo, limb_hi):
                    for b in (LIMB_BONES[limb, 0], LIMB_BONES[limb, 1]):
                        for c in range(3):
                            d[b, c] = out[base, b, c]
            else:
                d[:] = out[base]
            c, s = cos_a[n], sin_a[n]
            if trunk:
                _trunk_noise(d, c, s)
            for limb in range(limb_lo, limb_hi):
                u, lo = LIMB_BONES[limb, 0], LIMB_BONES[limb, 1]
                k = 5 + 3 * limb
                u0, u1, u2 = d[u, 0], d[u, 1], d[u, 2]
                h0, h1, h2 = u1 * d[lo, 2] - u2 * d[lo, 1], u2 * d[lo, 0] - u0 * d[lo, 2], u0 * d[lo, 1] - u1 * d[lo, 0]
                if h0 * h0 + h1 * h1 + h2 * h2 < 1e-6:  # straight limb: bend about the ball axis
                    h0, h1, h2 = _ball_axis(u0, u1, u2)
                h0, h1, h2 = _unit3(h0, h1, h2)
                l0, l1, l2 = _rot3cs(d[lo, 0], d[lo, 1], d[lo, 2], h0, h1, h2, c[k + 2], s[k + 2])  # hinge
                r0, r1, r2 = _ball_axis(u0, u1, u2)
                v0, v1, v2 = _rot3cs(u0, u1, u2, r0, r1, r2, c[k], s[k])                     # ball, upper
                d[u, 0], d[u, 1], d[u, 2] = _rot3cs(v0, v1, v2, u0, u1, u2, c[k + 1], s[k + 1])
                v0, v1, v2 = _rot3cs(l0, l1, l2, r0, r1, r2, c[k], s[k])                     # ball carries lower
                d[lo, 0], d[lo, 1], d[lo, 2] = _rot3cs(v0, v1, v2, u0, u1, u2, c[k + 1], s[k + 1])
            p += 1


@njit(cache=True, fastmath=FAST)
def body_joints(dirs, lengths, out):
    """Torso-frame joints out (13, 3) of directions (11, 3) and lengths (8,)."""
    hs = 0.5 * lengths[0]
    for c in range(3):
        out[LS, c] = 0.0
        out[RS, c] = 0.0
    out[LS, 0] = hs
    out[RS, 0] = -hs
    for c in range(3):
        out[HEAD, c] = lengths[3] * dirs[NECK, c]
        hm = lengths[2] * dirs[SPINE, c]
        out[LH, c] = hm + 0.5 * lengths[1] * dirs[PELVIS, c]
        out[RH, c] = hm - 0.5 * lengths[1] * dirs[PELVIS, c]
        out[LE, c] = out[LS, c] + lengths[4] * dirs[LUA, c]
        out[LW, c] = out[LE, c] + lengths[5] * dirs[LFA, c]
        out[RE, c] = out[RS, c] + lengths[4] * dirs[RUA, c]
        out[RW, c] = out[RE, c] + lengths[5] * dirs[RFA, c]
        out[LK, c] = out[LH, c] + lengths[6] * dirs[LTH, c]
        out[LA, c] = out[LK, c] + lengths[7] * dirs[LSH, c]
        out[RK, c] = out[RH, c] + lengths[6] * dirs[RTH, c]
        out[RA, c] = out[RK, c] + lengths[7] * dirs[RSH, c]


# marker model (samba_common.markerset): side, segment (0 torso, 1 forearm, 2 shank), limb bones
M_SIDE = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
M_SEG = np.array([0, 0, 1, 1, 2, 2, 2, 2])
M_UPPER = np.array([-1, -1, LUA, RUA, LTH, RTH, LTH, RTH])
M_LOWER = np.array([-1, -1, LFA, RFA, LSH, RSH, LSH, RSH])
HINGE_BLEND = 0.2


@njit(cache=True, fastmath=FAST)
def marker_offsets_body(dirs, offsets, w):
    """Offsets of the 8 markers in torso coordinates, w (8, 3), from directions (11, 3) and the
    offsets (8, 3) in segment frames (samba_common.markerset.segment_frames_body, same definition)."""
    for i in range(8):
        s = M_SIDE[i]
        a0, a1, a2 = offsets[i, 0], offsets[i, 1], offsets[i, 2]
        if a0 == 0.0 and a1 == 0.0 and a2 == 0.0:
            w[i, 0], w[i, 1], w[i, 2] = 0.0, 0.0, 0.0
            continue
        if M_SEG[i] == 0:
            w[i, 0], w[i, 1], w[i, 2] = s * a0, a1, a2
            continue
        u, lo = M_UPPER[i], M_LOWER[i]
        k = HINGE_BLEND if M_SEG[i] == 1 else -HINGE_BLEND
        l0, l1, l2 = dirs[lo, 0], dirs[lo, 1], dirs[lo, 2]
        v0, v1, v2 = l0, l1, l2 + k
        h0 = dirs[u, 1] * v2 - dirs[u, 2] * v1
        h1 = dirs[u, 2] * v0 - dirs[u, 0] * v2
        h2 = dirs[u, 0] * v1 - dirs[u, 1] * v0
        p0, p1, p2 = -l0, -l1, -l2
        dot = h0 * p0 + h1 * p1 + h2 * p2
        h0, h1, h2 = h0 - dot * p0, h1 - dot * p1, h2 - dot * p2
        if h0 * h0 + h1 * h1 + h2 * h2 < 1e-18:
            dot = p0
            h0, h1, h2 = 1.0 - dot * p0, -dot * p1, -dot * p2
        h0, h1, h2 = _unit3(h0, h1, h2)
        sg = -s if M_SEG[i] == 1 else s
        e10, e11, e12 = sg * h0, sg * h1, sg * h2
        e30 = s * (e11 * p2 - e12 * p1)
        e31 = s * (e12 * p0 - e10 * p2)
        e32 = s * (e10 * p1 - e11 * p0)
        w[i, 0] = a0 * e10 + a1 * p0 + a2 * e30
        w[i, 1] = a0 * e11 + a1 * p1 + a2 * e31
        w[i, 2] = a0 * e12 + a1 * p2 + a2 * e32


@njit(cache=True, fastmath=FAST)
def body_markers(dirs, lengths, offsets, body, mb, w):
    """Torso-frame markers mb (8, 3) = joint centres + offsets; fills body (13, 3) joints and w (8, 3)."""
    body_joints(dirs, lengths, body)
    marker_offsets_body(dirs, offsets, w)
    for i in range(8):
        for c in range(3):
            mb[i, c] = body[MARKER_JOINTS[i], c] + w[i, c]


@njit(cache=True, fastmath=FAST)
def world_markers(R, o, dirs, lengths, offsets, out):
    """World markers out (8, 3) of a state (R, o, dirs)."""
    body = np.empty((13, 3))
    mb = np.empty((8, 3))
    w = np.empty((8, 3))
    body_markers(dirs, lengths, offsets, body, mb, w)
    for i in range(8):
        for c in range(3):
            out[i, c] = o[c] + R[c, 0] * mb[i, 0] + R[c, 1] * mb[i, 1] + R[c, 2] * mb[i, 2]


@njit(cache=True, fastmath=FAST)
def marker_axes(m):
    """Marker body frame (3, 3) (columns x, y, z) of 8 markers (8, 3) in any coordinates:
    x = right->left shoulder, y = up from the ankle (else knee) midpoint, else world Z, else
    world Y (the first with at least 20 % of its length orthogonal to x), z = x cross y."""
    x0, x1, x2 = _unit3(m[0, 0] - m[1, 0], m[0, 1] - m[1, 1], m[0, 2] - m[1, 2])
    y0, y1, y2 = 0.0, 1.0, 0.0
    for cand in range(4):
        if cand < 2:
            a, b = (6, 7) if cand == 0 else (4, 5)
            u0 = 0.5 * (m[0, 0] + m[1, 0] - m[a, 0] - m[b, 0])
            u1 = 0.5 * (m[0, 1] + m[1, 1] - m[a, 1] - m[b, 1])
            u2 = 0.5 * (m[0, 2] + m[1, 2] - m[a, 2] - m[b, 2])
        elif cand == 2:
            u0, u1, u2 = 0.0, 0.0, 1.0
        else:
            u0, u1, u2 = 0.0, 1.0, 0.0
        dot = u0 * x0 + u1 * x1 + u2 * x2
        p0, p1, p2 = u0 - dot * x0, u1 - dot * x1, u2 - dot * x2
        pn = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        if pn >= 0.2 * math.sqrt(u0 * u0 + u1 * u1 + u2 * u2) and pn > 1e-9:
            y0, y1, y2 = p0 / pn, p1 / pn, p2 / pn
            break
    A = np.empty((3, 3))
    A[0, 0], A[1, 0], A[2, 0] = x0, x1, x2
    A[0, 1], A[1, 1], A[2, 1] = y0, y1, y2
    A[0, 2], A[1, 2], A[2, 2] = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    return A


@njit(cache=True, fastmath=FAST)
def pose_vectors(pool, lengths, offsets, X, frame=True):
    """X[:, :39]: vec(dirs) and (when ``frame``) the torso y, z axes in each pose's marker body
    frame, for pool poses (P, 11, 3); X is (P, 42), its last 3 columns are filled by the caller."""
    body = np.empty((13, 3))
    m = np.empty((8, 3))
    w = np.empty((8, 3))
    for p in range(pool.shape[0]):
        for b in range(11):
            for c in range(3):
                X[p, 3 * b + c] = pool[p, b, c]
        if not frame:
            continue
        body_markers(pool[p], lengths, offsets, body, m, w)
        y0, y1, y2, z0, z1, z2 = _frame_rows(m)
        X[p, 33], X[p, 34], X[p, 35] = y0, y1, y2
        X[p, 36], X[p, 37], X[p, 38] = z0, z1, z2


@njit(cache=True, fastmath=FAST)
def _frame_rows(m):
    """Rows 1 and 2 of the marker axes matrix of markers m (8, 3) (see :func:`marker_axes`):
    the torso y and z axes expressed in the marker frame, when m is in torso coordinates."""
    A = marker_axes(m)
    return A[1, 0], A[1, 1], A[1, 2], A[2, 0], A[2, 1], A[2, 2]


@njit(cache=True, fastmath=FAST)
def gaussian_block(X, dims, floor2, weight, mu, W):
    """Local PCA prior of the pose-vector entries ``dims``: writes their mean into mu (42,) and
    the whitening block sqrt(weight) L^-1 into W (42, 42), where L L^T = C + floor2 I and C is
    the covariance of the pooled poses X (P, 42) (the eigen-structure of C is the local PCA;
    floor2 keeps directions the pool does not span from being forbidden)."""
    P, d = X.shape[0], dims.shape[0]
    sub = np.empty((d, P))
    for i in range(d):
        col = dims[i]
        m = 0.0
        for p in range(P):
            m += X[p, col]
        m /= P
        mu[col] = m
        for p in range(P):
            sub[i, p] = X[p, col] - m
    C = np.dot(sub, sub.T) / max(P - 1, 1)
    for i in range(d):
        C[i, i] += floor2
    Lc = np.empty((d, d))
    if not _cholesky(C, Lc):  # cannot happen with floor2 > 0; keep a flat prior if it does
        for i in range(d):
            for j in range(d):
                W[dims[i], dims[j]] = 0.0
        return
    # inverse of the lower-triangular factor by forward substitution
    Li = np.zeros((d, d))
    for j in range(d):
        Li[j, j] = 1.0 / Lc[j, j]
        for i in range(j + 1, d):
            acc = 0.0
            for m in range(j, i):
                acc += Lc[i, m] * Li[m, j]
            Li[i, j] = -acc / Lc[i, i]
    sw = math.sqrt(weight)
    for i in range(d):
        for j in range(d):
            W[dims[i], dims[j]] = Li[i, j] * sw


@njit(cache=True, fastmath=FAST)
def linear_start(pool, lengths, offsets, obs_torso, seen):
    """The thesis' start: directions (11, 3) blending the pool so its markers best match the
    observed markers ``obs_torso`` (8, 3) (torso coordinates of the reference pose; rows where
    ``seen`` is False are ignored) in the ridge-regularised least-squares sense."""
    P = pool.shape[0]
    n_seen = 0
    for i in range(8):
        if seen[i]:
            n_seen += 1
    A = np.empty((3 * n_seen, P))
    b = np.empty(3 * n_seen)
    body = np.empty((13, 3))
    mb = np.empty((8, 3))
    w = np.empty((8, 3))
    for p in range(P):
        body_markers(pool[p], lengths, offsets, body, mb, w)
        r = 0
        for i in range(8):
            if seen[i]:
                for c in range(3):
                    A[r, p] = mb[i, c]
                    r += 1
    r = 0
    for i in range(8):
        if seen[i]:
            for c in range(3):
                b[r] = obs_torso[i, c]
                r += 1
    AAt = np.dot(A, A.T)
    tr = 0.0
    for i in range(3 * n_seen):
        tr += AAt[i, i]
    lam = 1e-3 * tr / max(3 * n_seen, 1) + 1e-12
    for i in range(3 * n_seen):
        AAt[i, i] += lam
    x = np.empty(3 * n_seen)
    if not _chol_solve(AAt, b, x):
        x[:] = 0.0
    gamma = np.dot(A.T, x)
    d = np.zeros((11, 3))
    for p in range(P):
        gp = gamma[p]
        for bone in range(11):
            for c in range(3):
                d[bone, c] += gp * pool[p, bone, c]
    for bone in range(11):
        n = math.sqrt(d[bone, 0] ** 2 + d[bone, 1] ** 2 + d[bone, 2] ** 2)
        if n > 1e-6:
            d[bone] /= n
        else:
            d[bone] = pool[0, bone]
    d[SPINE, 2] = 0.0
    d[SPINE] = _normalize(d[SPINE])
    return d


@njit(cache=True, fastmath=FAST)
def _tangents(dirs):
    """Tangent bases (11, 2, 3) of unit directions (11, 3); the spine's first tangent is its lean."""
    T = np.empty((11, 2, 3))
    for b in range(11):
        d0, d1, d2 = dirs[b, 0], dirs[b, 1], dirs[b, 2]
        if b == SPINE:
            e0, e1, e2 = _unit3(-d1, d0, 0.0)  # z x d
        elif abs(d0) < 0.9:  # helper axis x, made orthogonal to d
            e0, e1, e2 = _unit3(1.0 - d0 * d0, -d0 * d1, -d0 * d2)
        else:  # helper axis y
            e0, e1, e2 = _unit3(-d1 * d0, 1.0 - d1 * d1, -d1 * d2)
        T[b, 0, 0], T[b, 0, 1], T[b, 0, 2] = e0, e1, e2
        T[b, 1, 0], T[b, 1, 1], T[b, 1, 2] = d1 * e2 - d2 * e1, d2 * e0 - d0 * e2, d0 * e1 - d1 * e0
    return T


@njit(cache=True, fastmath=FAST)
def _world(R, o, dirs, lengths, q):
    body = np.empty((13, 3))
    body_joints(dirs, lengths, body)
    for j in range(13):
        for i in range(3):
            q[j, i] = o[i] + R[i, 0] * body[j, 0] + R[i, 1] * body[j, 1] + R[i, 2] * body[j, 2]
    return body


@njit(cache=True, fastmath=FAST)
def _residuals(R, o, dirs, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s, q, r):
    _world(R, o, dirs, lengths, q)
    w = np.empty((8, 3))
    marker_offsets_body(dirs, offsets, w)
    v = np.empty(42)
    for b in range(11):
        for c in range(3):
            v[3 * b + c] = dirs[b, c] - mu[3 * b + c]
    M = _mat3(RA.T, R)
    for c in range(3):
        v[33 + c] = M[c, 1] - mu[33 + c]
        v[36 + c] = M[c, 2] - mu[36 + c]
        v[39 + c] = R[2, c] - mu[39 + c]  # world up in torso coordinates: R^T z
    r[:42] = np.dot(W, v)
    k = 42
    for i in range(8):
        if seen[i]:
            for c in range(3):
                m = q[MARKER_JOINTS[i], c] + R[c, 0] * w[i, 0] + R[c, 1] * w[i, 1] + R[c, 2] * w[i, 2]
                r[k] = (m - obs[i, c]) / sigma_m[i]
                k += 1
    if smooth:
        for j in range(13):
            for c in range(3):
                r[k] = (q[j, c] - target[j, c]) / sigma_s
                k += 1
    cost = 0.0
    for i in range(r.shape[0]):
        cost += r[i] * r[i]
    return cost


@njit(cache=True, fastmath=FAST)
def _jacobian(R, dirs, lengths, offsets, W, RA, seen, sigma_m, smooth, sigma_s, Gm, T, Jm, Jq, body):
    """Fill Jm (n_res, 27) with the Jacobian of :func:`_residuals`; Jq (13, 3, 27) and body
    (13, 3) are work arrays. A marker offset turns with its segment: with the torso exactly, with
    its lower limb bone as that bone's direction turns (the small change of the hinge axis is
    left out; the step is accepted on the exact energy)."""
    body_joints(dirs, lengths, body)
    w = np.empty((8, 3))
    marker_offsets_body(dirs, offsets, w)
    Jq[:] = 0.0
    for j in range(13):
        b0, b1, b2 = body[j, 0], body[j, 1], body[j, 2]
        for i in range(3):  # rotation: R (e_k x b); e_x x b = (0, -b2, b1) etc.
            Jq[j, i, 0] = -R[i, 1] * b2 + R[i, 2] * b1
            Jq[j, i, 1] = R[i, 0] * b2 - R[i, 2] * b0
            Jq[j, i, 2] = -R[i, 0] * b1 + R[i, 1] * b0
            Jq[j, i, 3 + i] = 1.0
    Jm[:42] = 0.0
    for b in range(11):
        L = lengths[BONE_LENGTH[b]]
        for kk in range(2):
            col = param_col(b, kk)
            if col < 0:
                continue
            t0, t1, t2 = T[b, kk, 0], T[b, kk, 1], T[b, kk, 2]
            w0 = L * (R[0, 0] * t0 + R[0, 1] * t1 + R[0, 2] * t2)
            w1 = L * (R[1, 0] * t0 + R[1, 1] * t1 + R[1, 2] * t2)
            w2 = L * (R[2, 0] * t0 + R[2, 1] * t1 + R[2, 2] * t2)
            for j in range(13):
                g = Gm[j, 1 + b]
                if g != 0.0:
                    Jq[j, 0, col] = g * w0
                    Jq[j, 1, col] = g * w1
                    Jq[j, 2, col] = g * w2
            for r in range(42):  # prior: W @ (tangent in the rows of bone b)
                Jm[r, col] = W[r, 3 * b] * t0 + W[r, 3 * b + 1] * t1 + W[r, 3 * b + 2] * t2
    M = _mat3(RA.T, R)
    u0, u1, u2 = R[2, 0], R[2, 1], R[2, 2]  # world up in torso coordinates
    for r in range(42):  # prior: torso y, z axes in the marker frame; world up (u x e_k)
        wy0, wy1, wy2 = W[r, 33], W[r, 34], W[r, 35]
        wz0, wz1, wz2 = W[r, 36], W[r, 37], W[r, 38]
        wu0, wu1, wu2 = W[r, 39], W[r, 40], W[r, 41]
        Jm[r, 0] = (wy0 * M[0, 2] + wy1 * M[1, 2] + wy2 * M[2, 2] - (wz0 * M[0, 1] + wz1 * M[1, 1] + wz2 * M[2, 1])
                    + wu1 * u2 - wu2 * u1)
        Jm[r, 1] = wz0 * M[0, 0] + wz1 * M[1, 0] + wz2 * M[2, 0] - wu0 * u2 + wu2 * u0
        Jm[r, 2] = -(wy0 * M[0, 0] + wy1 * M[1, 0] + wy2 * M[2, 0]) + wu0 * u1 - wu1 * u0
    k = 42
    extra = np.zeros((3, 27))
    for i in range(8):
        if seen[i]:
            inv_m = 1.0 / sigma_m[i]
            j = MARKER_JOINTS[i]
            w0, w1, w2 = w[i, 0], w[i, 1], w[i, 2]
            has_w = w0 != 0.0 or w1 != 0.0 or w2 != 0.0
            if has_w:
                extra[:] = 0.0
                for c in range(3):  # rotation: R (e_k x w)
                    extra[c, 0] = -R[c, 1] * w2 + R[c, 2] * w1
                    extra[c, 1] = R[c, 0] * w2 - R[c, 2] * w0
                    extra[c, 2] = -R[c, 0] * w1 + R[c, 1] * w0
                lo = M_LOWER[i]
                if lo >= 0:
                    d0, d1, d2 = dirs[lo, 0], dirs[lo, 1], dirs[lo, 2]
                    for kk in range(2):
                        col = param_col(lo, kk)
                        t0, t1, t2 = T[lo, kk, 0], T[lo, kk, 1], T[lo, kk, 2]
                        a0, a1, a2 = d1 * t2 - d2 * t1, d2 * t0 - d0 * t2, d0 * t1 - d1 * t0  # axis d x t
                        b0, b1, b2 = a1 * w2 - a2 * w1, a2 * w0 - a0 * w2, a0 * w1 - a1 * w0  # (d x t) x w
                        for c in range(3):
                            extra[c, col] += R[c, 0] * b0 + R[c, 1] * b1 + R[c, 2] * b2
            for c in range(3):
                if has_w:
                    for col in range(27):
                        Jm[k, col] = (Jq[j, c, col] + extra[c, col]) * inv_m
                else:
                    for col in range(27):
                        Jm[k, col] = Jq[j, c, col] * inv_m
                k += 1
    if smooth:
        inv_s = 1.0 / sigma_s
        for j in range(13):
            for c in range(3):
                for col in range(27):
                    Jm[k, col] = Jq[j, c, col] * inv_s
                k += 1


@njit(cache=True, fastmath=FAST)
def _mat3(A, B):
    """3x3 product without a BLAS call."""
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
    return C


@njit(cache=True, fastmath=FAST)
def _expm(w):
    """Rotation matrix of the rotation vector w (3,) (Rodrigues)."""
    th = math.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2)
    E = np.eye(3)
    if th < 1e-12:
        return E
    k0, k1, k2 = w[0] / th, w[1] / th, w[2] / th
    s, c1 = math.sin(th), 1.0 - math.cos(th)
    E[0, 0] -= c1 * (k1 * k1 + k2 * k2)
    E[1, 1] -= c1 * (k0 * k0 + k2 * k2)
    E[2, 2] -= c1 * (k0 * k0 + k1 * k1)
    E[0, 1], E[1, 0] = -s * k2 + c1 * k0 * k1, s * k2 + c1 * k0 * k1
    E[0, 2], E[2, 0] = s * k1 + c1 * k0 * k2, -s * k1 + c1 * k0 * k2
    E[1, 2], E[2, 1] = -s * k0 + c1 * k1 * k2, s * k0 + c1 * k1 * k2
    return E


@njit(cache=True, fastmath=FAST)
def _step(R, o, dirs, delta, T):
    """Apply a tangent step (27,) to (R, o, dirs)."""
    R2 = _mat3(R, _expm(delta[:3]))
    o2 = o + delta[3:6]
    d2 = dirs.copy()
    for b in range(11):
        for kk in range(2):
            col = param_col(b, kk)
            if col >= 0:
                for c in range(3):
                    d2[b, c] += delta[col] * T[b, kk, c]
        d2[b, 0], d2[b, 1], d2[b, 2] = _unit3(d2[b, 0], d2[b, 1], d2[b, 2])
    return R2, o2, d2


@njit(cache=True, fastmath=FAST)
def _cholesky(M, L):
    """Lower-triangular L (n, n) with L L^T = M for symmetric positive definite M; False when M
    is not positive definite (L is then undefined)."""
    n = M.shape[0]
    for j in range(n):
        s = M[j, j]
        for m in range(j):
            s -= L[j, m] * L[j, m]
        if s <= 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = M[i, j]
            for m in range(j):
                s -= L[i, m] * L[j, m]
            L[i, j] = s / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True, fastmath=FAST)
def _chol_solve(M, rhs, out):
    """Solve M x = rhs for symmetric positive definite M (n, n) by Cholesky, into out (n,).
    Returns False (out undefined) when M is not positive definite."""
    n = M.shape[0]
    L = np.empty((n, n))
    if not _cholesky(M, L):
        return False
    for i in range(n):  # forward: L y = rhs
        s = rhs[i]
        for m in range(i):
            s -= L[i, m] * out[m]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):  # back: L^T x = y
        s = out[i]
        for m in range(i + 1, n):
            s -= L[m, i] * out[m]
        out[i] = s / L[i, i]
    return True


@njit(cache=True, fastmath=FAST)
def lm_solve(R, o, dirs, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s, Gm, max_iter, tol):
    """Levenberg-Marquardt from (R, o, dirs). Returns (R, o, dirs, q (13, 3), iterations, cost)."""
    n_seen = 0
    for i in range(8):
        if seen[i]:
            n_seen += 1
    n_res = 42 + 3 * n_seen + (39 if smooth else 0)
    r = np.empty(n_res)
    r_new = np.empty(n_res)
    q = np.empty((13, 3))
    q_new = np.empty((13, 3))
    Jm = np.empty((n_res, 27))
    Jq = np.empty((13, 3, 27))
    body = np.empty((13, 3))
    delta = np.empty(27)
    Ad = np.empty((27, 27))
    mg = np.empty(27)
    cost = _residuals(R, o, dirs, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s, q, r)
    lam = 1e-3
    it = 0
    while it < max_iter:
        it += 1
        T = _tangents(dirs)
        _jacobian(R, dirs, lengths, offsets, W, RA, seen, sigma_m, smooth, sigma_s, Gm, T, Jm, Jq, body)
        A = np.dot(Jm.T, Jm)
        g = np.dot(Jm.T, r)
        accepted = False
        while lam <= 1e9:
            for i in range(27):  # LM damping: (A + lam diag(A)) delta = -g
                for j in range(27):
                    Ad[i, j] = A[i, j]
                Ad[i, i] += lam * (A[i, i] + 1e-9)
                mg[i] = -g[i]
            if not _chol_solve(Ad, mg, delta):
                lam *= 10.0
                continue
            R2, o2, d2 = _step(R, o, dirs, delta, T)
            cost_new = _residuals(R2, o2, d2, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s,
                                  q_new, r_new)
            if cost_new <= cost:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            break
        R, o, dirs = R2, o2, d2
        r[:] = r_new
        q[:] = q_new
        lam = max(lam * 0.2, 1e-9)
        done = cost - cost_new <= tol * (1.0 + cost)
        cost = cost_new
        if done:
            break
    return R, o, dirs, q, it, cost


@njit(cache=True, fastmath=FAST)
def energy(R, o, dirs, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s):
    """The energy of one state (for choosing between starts)."""
    n_seen = 0
    for i in range(8):
        if seen[i]:
            n_seen += 1
    r = np.empty(42 + 3 * n_seen + (39 if smooth else 0))
    q = np.empty((13, 3))
    return _residuals(R, o, dirs, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s, q, r)


@njit(cache=True, fastmath=FAST)
def solve_frame(db_dirs, db_up, nbrs, dims, n_dims, cos_a, sin_a, lengths, offsets, floor2, weight, R_nn, RA, origin,
                obs, seen, sigma_m, smooth, target, sigma_s, has_prev, R0, o0, d0, Gm, max_iter, tol):
    """One frame after the neighbour search, in one compiled call.

    db_dirs: (M, 11, 3) database directions; db_up: (M, 3) world up in each pose's torso frame;
    nbrs: (P, K) neighbour indices per body part; dims: (P, 42) pose-vector entries of each part
    (first n_dims[p] valid); the last part is the trunk (or the whole body when P == 1), parts 0
    and 1 the left and right arm. R_nn: (3, 3) marker axes in torso coordinates of the trunk's
    nearest pose; RA, origin: the observation's marker frame (world); obs (8, 3), seen (8,):
    observed markers; smooth/target/sigma_s: temporal term; has_prev/R0/o0/d0: the previous
    pose as a second start. Returns (R, o, dirs, q (13, 3), iterations).
    """
    P, K = nbrs.shape
    N = cos_a.shape[0]
    n_pool = K * (N + 1)
    mu = np.zeros(42)
    W = np.zeros((42, 42))
    pools = np.zeros((P, n_pool, 11, 3))
    X = np.empty((n_pool, 42))
    for part in range(P):
        arm = P == 3 and part < 2
        if arm:
            pseudo_pool(db_dirs, nbrs[part], cos_a, sin_a, pools[part], False, part, part + 1, True)
        elif P == 3:
            pseudo_pool(db_dirs, nbrs[part], cos_a, sin_a, pools[part], True, 2, 4)
        else:
            pseudo_pool(db_dirs, nbrs[part], cos_a, sin_a, pools[part], True, 0, 4)
        pose_vectors(pools[part], lengths, offsets, X, not arm)
        for p in range(n_pool):  # pseudo-poses keep their neighbour's orientation to gravity
            for c in range(3):
                X[p, 39 + c] = db_up[nbrs[part, p // (N + 1)], c]
        gaussian_block(X, dims[part, :n_dims[part]], floor2, weight, mu, W)
    pool = pools[P - 1].copy()
    if P == 3:  # the arms of the start come from their own pools
        for p in range(n_pool):
            for c in range(3):
                pool[p, LUA, c] = pools[0, p, LUA, c]
                pool[p, LFA, c] = pools[0, p, LFA, c]
                pool[p, RUA, c] = pools[1, p, RUA, c]
                pool[p, RFA, c] = pools[1, p, RFA, c]
    # observation in the torso coordinates of the nearest pose: ((x - origin) @ RA) @ R_nn.T
    obs_torso = np.zeros((8, 3))
    M = _mat3(RA, R_nn.T)  # torso axes of the nearest pose, in world coordinates
    for i in range(8):
        if seen[i]:
            for c in range(3):
                obs_torso[i, c] = ((obs[i, 0] - origin[0]) * M[0, c] + (obs[i, 1] - origin[1]) * M[1, c]
                                   + (obs[i, 2] - origin[2]) * M[2, c])
    Rs = M
    ds = linear_start(pool, lengths, offsets, obs_torso, seen)
    os_ = origin.copy()
    # the shoulder markers' midpoint sits at the mean shoulder offset from the joints' midpoint
    w_sh = np.array([0.5 * (offsets[0, 0] - offsets[1, 0]), 0.5 * (offsets[0, 1] + offsets[1, 1]),
                     0.5 * (offsets[0, 2] + offsets[1, 2])])
    for c in range(3):
        os_[c] -= M[c, 0] * w_sh[0] + M[c, 1] * w_sh[1] + M[c, 2] * w_sh[2]
    if has_prev:
        e_lin = energy(Rs, os_, ds, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s)
        e_prev = energy(R0, o0, d0, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target, sigma_s)
        if e_prev < e_lin:
            Rs, os_, ds = R0.copy(), o0.copy(), d0.copy()
    R, o, d, q, it, _cost = lm_solve(Rs, os_, ds, lengths, offsets, mu, W, RA, obs, seen, sigma_m, smooth, target,
                                     sigma_s, Gm, max_iter, tol)
    return R, o, d, q, it


@njit(cache=True, fastmath=FAST)
def search_feature(m, up_weight):
    """The pose-search feature of 8 world markers m (8, 3): (marker axes RA (3, 3), origin (3,)
    the shoulder midpoint, feature (27,): the markers in the marker body frame, then world up
    in that frame times ``up_weight``)."""
    RA = marker_axes(m)
    origin = 0.5 * (m[0] + m[1])
    feature = np.empty(27)
    for i in range(8):
        for c in range(3):
            feature[3 * i + c] = ((m[i, 0] - origin[0]) * RA[0, c] + (m[i, 1] - origin[1]) * RA[1, c]
                                  + (m[i, 2] - origin[2]) * RA[2, c])
    for c in range(3):
        feature[24 + c] = up_weight * RA[2, c]
    return RA, origin, feature


@njit(cache=True, fastmath=FAST)
def search_features(sets, up_weight):
    """:func:`search_feature` of each of sets (H, 8, 3) (complete marker sets): (H, 27)."""
    out = np.empty((sets.shape[0], 27))
    for h in range(sets.shape[0]):
        out[h] = search_feature(sets[h], up_weight)[2]
    return out


@njit(cache=True, fastmath=FAST)
def _partial_knn(features, cols, n_cols, feature, k):
    """Nearest poses on the finite entries of ``feature`` among columns cols[:n_cols] (brute force;
    used only when a marker is unseen and there is no prediction to fill it)."""
    N = features.shape[0]
    d = np.zeros(N)
    used = 0
    for i in range(n_cols):
        c = cols[i]
        if np.isfinite(feature[c]):
            used += 1
            for p in range(N):
                diff = features[p, c] - feature[c]
                d[p] += diff * diff
    if used == 0:  # nothing of this part seen: use every seen coordinate
        for c in range(feature.shape[0]):
            if np.isfinite(feature[c]):
                for p in range(N):
                    diff = features[p, c] - feature[c]
                    d[p] += diff * diff
    return np.argsort(d)[:k]


@njit(cache=True, fastmath=FAST)
def frame(markers, has_pred, n_hist, q1, q2, m1, m2, has_state, R0, o0, d0, dt, trees, features, feat_cols, n_cols,
          up_weight, R_A_db, db_dirs, db_up, k, dims, n_dims, cos_a, sin_a, lengths, offsets, floor2, weight, sigma_m, accel,
          smooth_floor,
          min_markers,
          Gm, max_iter, tol):
    """The whole per-frame solve in one compiled call.

    markers: (8, 3) world metres, NaN rows unseen. History: n_hist (0-2) previous poses q1 (last),
    q2 (13, 3), and their model markers m1, m2 (8, 3) (which fill unseen markers); has_pred: whether they are recent enough to predict from; has_state/R0/o0/d0: the
    last solved state; dt: seconds since the last pose. trees: per body part, the KD-tree arrays
    (see :mod:`samba_server.recon.kdtree`) over ``features`` (M, 27) columns feat_cols[p, :n_cols[p]]
    (24 aligned marker coordinates, then world up in the marker frame times ``up_weight``).
    offsets: (8, 3) marker offsets in segment frames (zeros: markers on the joint centres).
    sigma_m: (8,) each marker's noise (m).
    Returns (status, q (13, 3), R, o, dirs, iterations, rms marker residual, markers seen, model
    markers (8, 3)) with status 0 = solved, 1 = bridged (too few markers, temporal model), 2 = unsolved.
    """
    q = np.full((13, 3), np.nan)
    mk = np.full((8, 3), np.nan)
    seen = np.zeros(8, dtype=np.bool_)
    n_seen = 0
    for i in range(8):
        seen[i] = np.isfinite(markers[i, 0]) and np.isfinite(markers[i, 1]) and np.isfinite(markers[i, 2])
        if seen[i]:
            n_seen += 1
    bridged = n_seen < min_markers
    if bridged and not has_pred:
        return 2, q, R0, o0, d0, 0, np.nan, n_seen, mk
    filled = markers.copy()
    obs = np.zeros((8, 3))
    for i in range(8):
        if seen[i]:
            obs[i] = markers[i]
        elif has_pred:
            for c in range(3):
                filled[i, c] = m1[i, c] if n_hist == 1 else 2.0 * m1[i, c] - m2[i, c]
    for c in range(3):
        if not (np.isfinite(filled[0, c]) and np.isfinite(filled[1, c])):
            return 2, q, R0, o0, d0, 0, np.nan, n_seen, mk
    if filled[0, 0] == filled[1, 0] and filled[0, 1] == filled[1, 1] and filled[0, 2] == filled[1, 2]:
        return 2, q, R0, o0, d0, 0, np.nan, n_seen, mk
    RA, origin, feature = search_feature(filled, up_weight)
    P = len(trees)
    nbrs = np.empty((P, k), dtype=np.int64)
    for part in range(P):
        cols = feat_cols[part, :n_cols[part]]
        sub = np.empty(cols.shape[0])
        ok = True
        for i in range(cols.shape[0]):
            sub[i] = feature[cols[i]]
            ok = ok and np.isfinite(sub[i])
        if ok:
            tr = trees[part]
            nbrs[part] = knn(tr[0], tr[1], tr[2], tr[3], tr[4], tr[5], tr[6], tr[7], tr[8], tr[9], tr[10], tr[11], sub, k)
        else:
            nbrs[part] = _partial_knn(features, feat_cols[part], n_cols[part], feature, k)
    smooth = n_hist == 2 and dt > 0
    target = np.zeros((13, 3))
    if smooth:
        target = 2.0 * q1 - q2
    o_start = o0.copy()
    if has_state and n_hist == 2:  # the shoulder midpoint moves on at constant velocity
        o_start += 0.5 * (q1[LS] + q1[RS] - q2[LS] - q2[RS])
    sigma_s = math.sqrt((accel * dt * dt) ** 2 + smooth_floor ** 2)
    R, o, d, q, it = solve_frame(db_dirs, db_up, nbrs, dims, n_dims, cos_a, sin_a, lengths, offsets, floor2, weight,
                                 R_A_db[nbrs[P - 1, 0]], RA, origin, obs, seen, sigma_m, smooth, target, sigma_s,
                                 has_state and has_pred, R0, o_start, d0, Gm, max_iter, tol)
    world_markers(R, o, d, lengths, offsets, mk)
    acc = 0.0
    for i in range(8):
        if seen[i]:
            for c in range(3):
                e = mk[i, c] - markers[i, c]
                acc += e * e
    resid = math.sqrt(acc / n_seen) if n_seen else np.nan
    return (1 if bridged else 0), q, R, o, d, it, resid, n_seen, mk
