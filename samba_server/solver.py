"""The per-frame energy and its Levenberg–Marquardt minimiser.

State: torso rotation ``R`` (3, 3), shoulder midpoint ``o`` (3,) metres, bone directions
``dirs`` (11, 3) in the torso frame; bone lengths are fixed per subject. The energy is

    E = |W (vec(dirs) - mu)|^2                      local PCA prior (Gaussian over directions)
      + sum_m |(q_m - x_m) / sigma_m|^2             marker fit (observed markers only)
      + sum_j |(q_j - 2 q_j' + q_j'') / sigma_s|^2  temporal smoothness (second difference)

with q the world joints of the state. LM steps in a 27-dimensional tangent space: a rotation
vector for ``R`` (3), a translation (3), the spine lean (1) and two tangent angles for each of the
other 10 bone directions (20). Jacobians are analytic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba_common.body import BONE_DIRS, D, L, LIMBS
from samba_common.skeleton import J, MARKER_JOINT, N_JOINTS

N_BONES = len(BONE_DIRS)
N_PARAMS = 6 + 1 + 2 * (N_BONES - 1)

# incidence matrix: body joints (13, 3) = G (13, 12) @ S (12, 3), S = [half shoulder line; L_b * d_b]
_G = np.zeros((N_JOINTS, 1 + N_BONES))
_G[J["left_shoulder"], 0] = 1.0
_G[J["right_shoulder"], 0] = -1.0
_G[J["head"], 1 + D["neck"]] = 1.0
for _s, _sign in (("left", 0.5), ("right", -0.5)):
    _G[J[f"{_s}_hip"], 1 + D["spine"]] = 1.0
    _G[J[f"{_s}_hip"], 1 + D["pelvis"]] = _sign
for _side, _up, _lo, _a, _b, _c, _lu, _ll in LIMBS:
    _G[J[_b]] = _G[J[_a]]
    _G[J[_b], 1 + D[_up]] = 1.0
    _G[J[_c]] = _G[J[_b]]
    _G[J[_c], 1 + D[_lo]] = 1.0
G = _G
#: length (BONE_TYPES index) that scales each direction
_BONE_LEN = np.array([L["neck"], L["hip_width"], L["torso"], L["upper_arm"], L["upper_arm"], L["forearm"],
                      L["forearm"], L["thigh"], L["thigh"], L["shin"], L["shin"]])
_MARKERS = np.array(MARKER_JOINT)
_SPINE = D["spine"]
# tangent columns: every bone has 2 except the spine, which keeps only its in-plane lean
_TAN_KEEP = np.array([k for k in range(2 * N_BONES) if k != 2 * _SPINE + 1])
_EX, _EY, _EZ = np.eye(3)


@dataclass
class State:
    """A pose: R (3, 3) torso axes as columns, o (3,) shoulder midpoint (m), dirs (11, 3) unit."""

    R: np.ndarray
    o: np.ndarray
    dirs: np.ndarray

    def copy(self) -> "State":
        return State(self.R.copy(), self.o.copy(), self.dirs.copy())


@dataclass
class Problem:
    """Everything fixed during one frame's solve.

    lengths: (8,) metres; mu: (39,) prior mean of the pose vector (vec(dirs), then the torso's y and
    z axes in the marker body frame); W: (39, 39) prior whitening matrix; RA: (3, 3) marker body
    frame of the observation (columns = axes in world); obs: (8, 3) observed markers (NaN rows
    ignored); sigma_m: marker noise (m);
    prev1, prev2: (13, 3) previous two solved poses or None; sigma_s: allowed second difference (m).
    """

    lengths: np.ndarray
    mu: np.ndarray
    W: np.ndarray
    RA: np.ndarray
    obs: np.ndarray
    sigma_m: float
    prev1: np.ndarray | None = None
    prev2: np.ndarray | None = None
    sigma_s: float = 0.02

    def __post_init__(self) -> None:
        self.seen = np.flatnonzero(np.all(np.isfinite(self.obs), axis=1))
        self.bone_len = self.lengths[_BONE_LEN]
        self.half_sw = 0.5 * self.lengths[L["shoulder_width"]]
        self.smooth = self.prev1 is not None and self.prev2 is not None
        if self.smooth:
            self.target = 2.0 * self.prev1 - self.prev2  # constant-velocity prediction (13, 3)


def tangents(dirs: np.ndarray) -> np.ndarray:
    """Tangent bases (11, 2, 3) of unit directions (11, 3); the spine's first tangent is its lean."""
    helper = np.where(np.abs(dirs[:, :1]) < 0.9, _EX, _EY)
    e1 = helper - np.sum(helper * dirs, axis=1, keepdims=True) * dirs
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e1[_SPINE] = np.cross(_EZ, dirs[_SPINE])
    e2 = np.cross(dirs, e1)
    return np.stack([e1, e2], axis=1)


def body_joints(dirs: np.ndarray, pb: Problem) -> np.ndarray:
    """Torso-frame joints (13, 3) of directions (11, 3)."""
    S = np.empty((1 + N_BONES, 3))
    S[0] = (pb.half_sw, 0.0, 0.0)
    S[1:] = pb.bone_len[:, None] * dirs
    return G @ S


def pose_vector(st: State, RA: np.ndarray) -> np.ndarray:
    """The prior's pose vector (39,): vec(dirs) and the torso y, z axes in the marker frame RA."""
    M = RA.T @ st.R
    return np.concatenate([st.dirs.reshape(-1), M[:, 1], M[:, 2]])


def residuals(st: State, pb: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Residual vector of the energy and the world joints (13, 3) of state ``st``."""
    q = st.o + body_joints(st.dirs, pb) @ st.R.T
    parts = [pb.W @ (pose_vector(st, pb.RA) - pb.mu),
             ((q[_MARKERS[pb.seen]] - pb.obs[pb.seen]) / pb.sigma_m).reshape(-1)]
    if pb.smooth:
        parts.append(((q - pb.target) / pb.sigma_s).reshape(-1))
    return np.concatenate(parts), q


def jacobian(st: State, pb: Problem, tan: np.ndarray) -> np.ndarray:
    """Jacobian (n_res, 27) of :func:`residuals` at ``st`` w.r.t. the tangent step."""
    body = body_joints(st.dirs, pb)
    # world joint derivatives (13, 3, 27)
    Jq = np.empty((N_JOINTS, 3, N_PARAMS))
    # rotation: d(R exp(w) b)/dw_k = R (e_k x b)
    Jq[:, :, 0:3] = np.einsum("ij,kpj->pik", st.R, np.cross(np.eye(3)[:, None, :], body[None]))
    Jq[:, :, 3:6] = np.eye(3)
    wt = np.einsum("ij,bkj->bki", st.R, tan * pb.bone_len[:, None, None]).reshape(2 * N_BONES, 3)[_TAN_KEEP]
    gcols = np.repeat(G[:, 1:], 2, axis=1)[:, _TAN_KEEP]  # (13, 21)
    Jq[:, :, 6:] = gcols[:, None, :] * wt.T[None, :, :]
    # prior: d vec(dirs)/d tangent
    E = np.zeros((3 * N_BONES, 2 * N_BONES))
    for b in range(N_BONES):
        E[3 * b:3 * b + 3, 2 * b] = tan[b, 0]
        E[3 * b:3 * b + 3, 2 * b + 1] = tan[b, 1]
    Jv = np.zeros((3 * N_BONES + 6, N_PARAMS))
    Jv[:3 * N_BONES, 6:] = E[:, _TAN_KEEP]
    M = pb.RA.T @ st.R
    # d(M exp(w) e_y)/dw = M (e_k x e_y): columns (e_z, 0, -e_x); for e_z: (-e_y, e_x, 0)
    Jv[3 * N_BONES:3 * N_BONES + 3, 0] = M[:, 2]
    Jv[3 * N_BONES:3 * N_BONES + 3, 2] = -M[:, 0]
    Jv[3 * N_BONES + 3:, 0] = -M[:, 1]
    Jv[3 * N_BONES + 3:, 1] = M[:, 0]
    Jp = pb.W @ Jv
    blocks = [Jp, (Jq[_MARKERS[pb.seen]] / pb.sigma_m).reshape(-1, N_PARAMS)]
    if pb.smooth:
        blocks.append((Jq / pb.sigma_s).reshape(-1, N_PARAMS))
    return np.concatenate(blocks, axis=0)


def _expm(w: np.ndarray) -> np.ndarray:
    th = np.sqrt(w @ w)
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


def step(st: State, delta: np.ndarray, tan: np.ndarray) -> State:
    """Apply a tangent step (27,) to a state."""
    full = np.zeros(2 * N_BONES)
    full[_TAN_KEEP] = delta[6:]
    coef = full.reshape(N_BONES, 2)
    d = st.dirs + coef[:, :1] * tan[:, 0] + coef[:, 1:] * tan[:, 1]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return State(st.R @ _expm(delta[:3]), st.o + delta[3:6], d)


def levenberg_marquardt(st: State, pb: Problem, max_iter: int = 20, tol: float = 1e-6,
                        lam: float = 1e-3) -> tuple[State, int, float, np.ndarray]:
    """Minimise the energy from ``st``. Returns (state, iterations, final cost, world joints (13, 3))."""
    r, q = residuals(st, pb)
    cost = r @ r
    it = 0
    for it in range(1, max_iter + 1):
        tan = tangents(st.dirs)
        Jm = jacobian(st, pb, tan)
        A = Jm.T @ Jm
        g = Jm.T @ r
        diag = np.diag(A).copy()
        while True:
            try:
                delta = np.linalg.solve(A + lam * np.diag(diag + 1e-9), -g)
            except np.linalg.LinAlgError:
                delta = None
            if delta is not None:
                cand = step(st, delta, tan)
                r_new, q_new = residuals(cand, pb)
                cost_new = r_new @ r_new
                if cost_new <= cost:
                    break
            lam *= 10.0
            if lam > 1e9:
                return st, it, float(cost), q
        st, r, q = cand, r_new, q_new
        lam = max(lam * 0.2, 1e-9)
        done = cost - cost_new <= tol * (1.0 + cost)
        cost = cost_new
        if done:
            break
    return st, it, float(cost), q
