"""Reconstruction of the 13-joint skeleton from 8 markers: one code path live and offline.

Per frame (:meth:`Reconstructor.solve`):

1. fill missing markers from the temporal prediction, align them in the body frame
   (:mod:`samba_common.align`);
2. K nearest database poses with a KD-tree over the database re-posed with the *subject's*
   bone lengths (:class:`PoseIndex`);
3. N pseudo-poses per neighbour (:mod:`samba_server.pseudo`);
4. local PCA over the pooled poses -> a Gaussian prior over bone directions;
5. Levenberg–Marquardt on PCA prior + marker fit + temporal smoothness
   (:mod:`samba_server.solver`), started from the better of the linear least-squares start of
   the thesis and the constant-velocity prediction;
6. joints in world coordinates with the subject's fixed bone lengths.

Offline, :func:`reconstruct_take` first estimates the subject's proportions from the whole take.
Live, the reconstructor estimates them from the first ``body_frames`` frames (the standard pose
that starts every take) and keeps them fixed afterwards.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from samba_common.align import AlignmentError, batch_frames, marker_frame
from samba_common.body import fk_body
from samba_common.skeleton import BONE_TYPES, MARKER_JOINT, N_JOINTS, N_MARKERS

from .db import MotionDB, load_default_db
from .proportions import ProportionError, estimate_lengths
from .pseudo import N_ANGLES, pseudo_poses
from .solver import Problem, State, levenberg_marquardt, residuals

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReconstructConfig:
    """Solver settings (``[reconstruct]`` in configs/reconstruct.toml).

    k: neighbours; pseudo: pseudo-poses per neighbour; ball_sigma_deg / hinge_sigma_deg: joint
    angle noise of pseudo-poses; prior_floor_deg: smallest standard deviation of a direction
    component in the prior; prior_weight: multiplies the prior energy; sigma_marker: marker
    noise (m); accel: typical joint acceleration (m/s^2) for the smoothness term; min_markers:
    fewer observed markers make a frame "bridged" by the temporal model; max_gap: longest bridge
    (s), beyond it frames are NaN; max_iter: LM iteration cap; body_frames: frames used to
    estimate the body live; seed: pseudo-pose noise bank seed.
    """

    k: int = 10
    pseudo: int = 10
    ball_sigma_deg: float = 6.0
    hinge_sigma_deg: float = 8.0
    prior_floor_deg: float = 8.0
    prior_weight: float = 0.5
    sigma_marker: float = 0.003
    accel: float = 30.0
    min_markers: int = 4
    max_gap: float = 0.3
    max_iter: int = 15
    body_frames: int = 30
    seed: int = 7


@dataclass
class PoseResult:
    """One solved frame. joints: (13, 3) world metres (all NaN if unsolved); residual: rms marker
    error (m) over the observed markers; n_markers: markers used; iterations: LM iterations;
    status: "solved", "bridged" or "unsolved"."""

    joints: np.ndarray
    residual: float
    n_markers: int
    iterations: int
    status: str


class PoseIndex:
    """KD-tree over the database poses re-posed with one subject's bone lengths.

    features: (N, 24) aligned markers (metres, body frame); R_A: (N, 3, 3) marker-frame axes in
    torso coordinates, to carry a neighbour's torso orientation into the world.
    """

    def __init__(self, db: MotionDB, lengths: np.ndarray):
        body = fk_body(db.dirs.astype(float), lengths)
        markers = body[:, list(MARKER_JOINT)]
        origin, R_A = batch_frames(markers)
        self.features = np.einsum("fpi,fij->fpj", markers - origin[:, None], R_A).reshape(len(db), -1)
        self.R_A = R_A
        self.tree = cKDTree(self.features)

    def query(self, feature: np.ndarray, k: int) -> np.ndarray:
        """Indices (k,) of the nearest poses to an aligned marker feature (24,)."""
        _d, idx = self.tree.query(feature, k=k)
        return np.atleast_1d(idx)

    def query_partial(self, feature: np.ndarray, seen: np.ndarray, k: int) -> np.ndarray:
        """Nearest poses using only the coordinates of seen markers (brute force, (8,) bool)."""
        cols = np.repeat(seen, 3)
        d = np.sum((self.features[:, cols] - feature[cols]) ** 2, axis=1)
        return np.argpartition(d, k)[:k] if k < len(d) else np.arange(len(d))


@dataclass
class _History:
    joints: list[np.ndarray] = field(default_factory=list)  # last two solved world poses
    state: State | None = None
    t_last: float = -np.inf   # time of the last solved or bridged frame
    t_seen: float = -np.inf   # time of the last frame with enough markers


def _local_prior(pool: np.ndarray, lengths: np.ndarray, floor: float, weight: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian over the pose vectors of pooled poses (P, 11, 3): mean (39,) and whitening W (39, 39).

    The pose vector is vec(dirs) followed by the torso's y and z axes expressed in the marker
    body frame, so the prior also knows how the torso sits relative to the legs.
    """
    _o, R_A = batch_frames(fk_body(pool, lengths)[:, list(MARKER_JOINT)])
    X = np.concatenate([pool.reshape(len(pool), -1), R_A[:, 1, :], R_A[:, 2, :]], axis=1)
    mu = X.mean(axis=0)
    C = np.cov(X, rowvar=False) if len(X) > 1 else np.zeros((X.shape[1], X.shape[1]))
    evals, evecs = np.linalg.eigh(C)
    evals = np.maximum(evals, 0.0) + floor**2
    W = (evecs / np.sqrt(evals)).T * np.sqrt(weight)
    return mu, W


class Reconstructor:
    """Per-frame 8-marker -> 13-joint solver with state (temporal model, subject proportions).

    db: motion database (default: the shipped one); lengths: (8,) subject bone lengths in
    BONE_TYPES order, or None to estimate them from the first ``config.body_frames`` frames.
    """

    def __init__(self, db: MotionDB | None = None, config: ReconstructConfig | None = None,
                 lengths: np.ndarray | None = None):
        self.db = db if db is not None else load_default_db()
        self.config = config or ReconstructConfig()
        rng = np.random.default_rng(self.config.seed)
        self._noise = rng.standard_normal((self.config.pseudo, N_ANGLES))
        self._estimating = lengths is None
        self._body_buffer: list[np.ndarray] = []
        self.lengths: np.ndarray | None = None
        self.index: PoseIndex | None = None
        self._hist = _History()
        if lengths is not None:
            self.set_lengths(lengths)

    # --- subject -------------------------------------------------------------------------
    def set_lengths(self, lengths: np.ndarray) -> None:
        """Fix the subject's bone lengths (8,) metres and re-pose the database with them."""
        lengths = np.asarray(lengths, dtype=float)
        if lengths.shape != (len(BONE_TYPES),) or not np.all(np.isfinite(lengths)) or np.any(lengths <= 0):
            raise ValueError(f"bone lengths must be 8 positive numbers, got {lengths}")
        self.lengths = lengths
        self.index = PoseIndex(self.db, lengths)

    def reset(self) -> None:
        """Forget the temporal history (a new take or a long gap); keeps the body."""
        self._hist = _History()

    # --- per frame -----------------------------------------------------------------------
    def solve(self, markers: np.ndarray, t: float) -> PoseResult:
        """Solve one frame. markers: (8, 3) world metres, NaN rows = unseen; t: seconds."""
        markers = np.asarray(markers, dtype=float).reshape(N_MARKERS, 3)
        if self._estimating:
            self._body_buffer.append(markers)
            n = len(self._body_buffer)
            if self.lengths is None or n % 10 == 0 or n >= self.config.body_frames:
                try:
                    self.set_lengths(estimate_lengths(np.array(self._body_buffer), self.db.mean_lengths))
                except ProportionError:
                    pass
            if n >= self.config.body_frames:
                self._estimating, self._body_buffer = False, []
            if self.lengths is None:
                return self._unsolved(int(np.all(np.isfinite(markers), axis=1).sum()))
        return self._solve(markers, float(t))

    def _unsolved(self, n: int) -> PoseResult:
        return PoseResult(np.full((N_JOINTS, 3), np.nan), float("nan"), n, 0, "unsolved")

    def _prediction(self, t: float) -> np.ndarray | None:
        h = self._hist
        if not h.joints or t - h.t_seen > self.config.max_gap:
            return None
        if len(h.joints) == 1:
            return h.joints[-1]
        return 2.0 * h.joints[-1] - h.joints[-2]

    def _solve(self, markers: np.ndarray, t: float) -> PoseResult:
        cfg = self.config
        assert self.lengths is not None and self.index is not None
        seen = np.all(np.isfinite(markers), axis=1)
        n_seen = int(seen.sum())
        pred = self._prediction(t)
        if pred is None and self._hist.joints:
            self.reset()
        bridged = n_seen < cfg.min_markers
        if bridged and pred is None:
            return self._unsolved(n_seen)
        filled = markers.copy()
        if pred is not None:
            filled[~seen] = pred[list(MARKER_JOINT)][~seen]
        try:
            frame = marker_frame(filled, scale=1.0)
        except AlignmentError:
            return self._unsolved(n_seen)
        feature = ((filled - frame.origin) @ frame.R).reshape(-1)
        k = min(cfg.k, len(self.db))
        if np.all(np.isfinite(feature)):
            nbr = self.index.query(feature, k)
        else:
            nbr = self.index.query_partial(np.nan_to_num(feature), np.all(np.isfinite(filled), axis=1), k)
        pool = pseudo_poses(self.db.dirs[nbr].astype(float), self._noise, np.radians(cfg.ball_sigma_deg),
                            np.radians(cfg.hinge_sigma_deg))
        mu, W = _local_prior(pool, self.lengths, np.radians(cfg.prior_floor_deg), cfg.prior_weight)
        h = self._hist
        dt = t - h.t_last if h.joints else 0.0
        smooth = len(h.joints) == 2 and dt > 0
        pb = Problem(self.lengths, mu, W, frame.R, markers, cfg.sigma_marker,
                     h.joints[-1] if smooth else None, h.joints[-2] if smooth else None,
                     sigma_s=max(cfg.accel * dt * dt, 1e-3))
        starts = [self._linear_start(frame, nbr, pool, markers, seen)]
        if h.state is not None and pred is not None:
            prev = h.state.copy()
            if len(h.joints) == 2:
                prev.o = prev.o + (h.joints[-1][1:3].mean(0) - h.joints[-2][1:3].mean(0))
            starts.append(prev)
        costs = [float(np.sum(residuals(s, pb)[0] ** 2)) for s in starts]
        st, iters, _cost, q = levenberg_marquardt(starts[int(np.argmin(costs))], pb, cfg.max_iter)
        err = q[list(MARKER_JOINT)][seen] - markers[seen]
        resid = float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if n_seen else float("nan")
        h.joints = (h.joints + [q])[-2:]
        h.state, h.t_last = st, t
        if not bridged:
            h.t_seen = t
        return PoseResult(q, resid, n_seen, iters, "bridged" if bridged else "solved")

    def _linear_start(self, frame, nbr: np.ndarray, pool: np.ndarray, markers: np.ndarray, seen: np.ndarray) -> State:
        """The thesis' start: observed markers as a least-squares blend of the pooled poses' markers."""
        body = fk_body(pool, self.lengths)[:, list(MARKER_JOINT)]          # (P, 8, 3) torso frame
        R_nn = self.index.R_A[nbr[0]]
        obs_torso = ((markers - frame.origin) @ frame.R) @ R_nn.T            # observed, in the nn's torso frame
        A = body[:, seen].reshape(len(pool), -1).T                            # (3S, P)
        b = obs_torso[seen].reshape(-1)
        lam = 1e-3 * np.trace(A @ A.T) / max(A.shape[0], 1) + 1e-12
        gamma = A.T @ np.linalg.solve(A @ A.T + lam * np.eye(A.shape[0]), b)
        d = np.tensordot(gamma, pool, axes=1)
        norms = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(norms > 1e-6, d / np.maximum(norms, 1e-12), pool[0])
        d[2, 2] = 0.0  # the spine stays in the torso's x-y plane
        d[2] /= np.linalg.norm(d[2])
        return State(frame.R @ R_nn.T, frame.origin.copy(), d)


def reconstruct_take(markers: np.ndarray, t: np.ndarray, db: MotionDB | None = None,
                     config: ReconstructConfig | None = None, lengths: np.ndarray | None = None,
                     progress=None) -> tuple[np.ndarray, dict]:
    """Reconstruct a whole take offline.

    markers: (F, 8, 3) world metres, NaN = unseen; t: (F,) seconds. lengths: subject bone lengths
    (8,), default: estimated from the whole take. progress: optional callable(n_frames_done).
    Returns joints (F, 13, 3) (NaN frames where unsolved) and an info dict with per-frame
    ``residual`` (F,), ``n_markers`` (F,), ``iterations`` (F,), ``status`` (F,) and the
    ``lengths`` (8,), ``ms_per_frame``.
    """
    db = db if db is not None else load_default_db()
    if lengths is None:
        lengths = estimate_lengths(markers, db.mean_lengths)
    rec = Reconstructor(db, config, lengths)
    F = len(t)
    joints = np.full((F, N_JOINTS, 3), np.nan)
    resid = np.full(F, np.nan)
    nmark = np.zeros(F, np.int16)
    iters = np.zeros(F, np.int16)
    status = np.empty(F, dtype="<U8")
    t0 = time.perf_counter()
    for i in range(F):
        r = rec.solve(markers[i], float(t[i]))
        joints[i], resid[i], nmark[i], iters[i], status[i] = r.joints, r.residual, r.n_markers, r.iterations, r.status
        if progress is not None:
            progress(1)
    elapsed = time.perf_counter() - t0
    info = {"residual": resid, "n_markers": nmark, "iterations": iters, "status": status,
            "lengths": np.asarray(lengths, float), "ms_per_frame": 1e3 * elapsed / max(F, 1)}
    return joints, info
