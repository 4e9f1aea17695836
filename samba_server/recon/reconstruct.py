"""Reconstruction of the 13-joint skeleton from 8 markers: one code path live and offline.

Per frame (:meth:`Reconstructor.solve`):

1. fill missing markers from the temporal prediction, align them in the body frame
   (:mod:`samba_common.align`);
2. K nearest database poses with a KD-tree over the database re-posed with the *subject's*
   bone lengths (:class:`PoseIndex`);
3. N pseudo-poses per neighbour (:mod:`samba_server.recon.kernels`);
4. local PCA over the pooled poses -> a Gaussian prior over bone directions;
5. Levenberg–Marquardt on PCA prior + marker fit + temporal smoothness
   (:mod:`samba_server.recon.kernels`), started from the better of the linear least-squares start of
   the thesis and the constant-velocity prediction;
6. joints in world coordinates with the subject's fixed bone lengths;
7. a bound per joint: how far it may be from the truth (:mod:`.bounds`).

Offline, :func:`reconstruct_take` first estimates the subject's proportions from the whole take.
Live, the reconstructor estimates them from the first ``body_frames`` frames (the standard pose
that starts every take) and keeps them fixed afterwards.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from samba_common.align import batch_frames
from samba_common.body import fk, standard_pose
from samba_common.markerset import OFFSET_SIGMA, TYPICAL_OFFSETS, body_markers, markers_from_joints
from samba_common.skeleton import BONE_TYPES, N_JOINTS, N_MARKERS
from samba_common.subject import Subject

from .db import MotionDB, load_default_db
from .proportions import ProportionError, estimate_lengths
from . import kernels
from .bounds import fresh_marker_state, joint_bounds, marker_bounds
from .kdtree import KDTree
from .live_subject import LiveSubjectCalibration, describe
from .subject_model import placement_from_standard_pose

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReconstructConfig:
    """Solver settings (``[reconstruct]`` in configs/reconstruct.toml).

    k: neighbours; pseudo: pseudo-poses per neighbour; ball_sigma_deg / hinge_sigma_deg: joint
    angle noise of pseudo-poses; prior_floor_deg: smallest standard deviation of a direction
    component in the prior; prior_weight: multiplies the prior energy; sigma_marker: marker
    noise (m); sigma_loose: noise (m) of a marker the labelling found only in merged blobs (its
    point may sit between two markers: about 2 cm rms on the labelling benchmark, 5 mm for the
    others); accel, smooth_floor: the smoothness term allows a second difference of
    hypot(accel * dt^2, smooth_floor) metres (typical acceleration, prediction noise); max_iter, tol: LM
    iteration cap and relative energy decrease that stops it; min_markers:
    fewer observed markers make a frame "bridged" by the temporal model; max_gap: longest bridge
    (s), beyond it frames are NaN; max_iter: LM iteration cap; body_frames: frames used to
    estimate the body live (see :meth:`Reconstructor._estimate_body`); seed: pseudo-pose noise bank seed.
    Live subject (a Reconstructor built without lengths and offsets, :mod:`.live_subject`):
    placement: "auto" (decided from the standard pose), "skin" or "joint_centres";
    subject_seconds: seconds of solved frames after the standard pose that calibrate the skin
    offsets and lengths; subject_refine_seconds: a second calibration from that many further
    seconds (0 = none); subject_swap_frames: frames between a calibration and its use (it is
    computed in a background thread; a replay swaps at the same frame).
    """

    k: int = 100
    pseudo: int = 1
    ball_sigma_deg: float = 6.0
    hinge_sigma_deg: float = 8.0
    prior_floor_deg: float = 5.0
    prior_weight: float = 0.5
    sigma_marker: float = 0.003
    sigma_loose: float = 0.01
    accel: float = 80.0
    smooth_floor: float = 0.01
    min_markers: int = 4
    max_gap: float = 0.3
    max_iter: int = 10
    tol: float = 1e-2
    body_frames: int = 30
    seed: int = 7
    parts: bool = True
    placement: str = "auto"
    subject_seconds: float = 1.0
    subject_refine_seconds: float = 4.0
    subject_swap_frames: int = 10

    def __post_init__(self) -> None:
        if self.placement not in ("auto", "skin", "joint_centres"):
            raise ValueError(f"placement must be auto, skin or joint_centres, got {self.placement!r}")


@dataclass
class PoseResult:
    """One solved frame. joints: (13, 3) world metres (all NaN if unsolved); residual: rms marker
    error (m) over the observed markers; n_markers: markers used; iterations: LM iterations;
    status: "solved", "bridged" or "unsolved"; state: the solved torso rotation (3, 3), shoulder
    midpoint (3,) and bone directions (11, 3), or None; bounds: (13,) metres, how far each
    joint may be from the truth (:mod:`.bounds`; inf when unsolved)."""

    joints: np.ndarray
    residual: float
    n_markers: int
    iterations: int
    status: str
    state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    bounds: np.ndarray = field(default_factory=lambda: np.full(N_JOINTS, np.inf))


#: feature columns (of the 24 aligned marker coordinates) and pose-vector entries of each body
#: part: left arm (left wrist), right arm (right wrist), trunk and legs (knees, ankles, gravity)
PART_FEATURES = (np.r_[6:9], np.r_[9:12], np.r_[12:27])
PART_DIMS = (np.r_[9:12, 15:18], np.r_[12:15, 18:21], np.r_[0:9, 21:42])
WHOLE = (np.r_[0:27], np.r_[0:42])
#: metres of marker distance that one unit of difference in the direction of gravity counts for
UP_WEIGHT = 1.0


class PoseIndex:
    """KD-trees over the database poses re-posed with one subject's bone lengths.

    features: (N, 27) aligned markers (metres, marker body frame) and world up in that frame
    times UP_WEIGHT (so the trunk search also matches the orientation to gravity); R_A: (N, 3, 3) marker-frame
    axes in torso coordinates, to carry a neighbour's torso orientation into the world.
    One tree over the whole feature and one per body part (:data:`PART_FEATURES`).
    """

    def __init__(self, db: MotionDB, lengths: np.ndarray, offsets: np.ndarray | None = None):
        markers = body_markers(db.dirs.astype(float), lengths, offsets)
        origin, R_A = batch_frames(markers)
        aligned = np.einsum("fpi,fij->fpj", markers - origin[:, None], R_A).reshape(len(db), -1)
        up = np.einsum("fij,fi->fj", R_A, db.up.astype(float))  # world up in the marker frame
        self.features = np.ascontiguousarray(np.concatenate([aligned, UP_WEIGHT * up], axis=1))
        self.R_A = np.ascontiguousarray(R_A)
        self._trees: dict[bytes, KDTree] = {}

    def tree(self, cols: np.ndarray) -> KDTree:
        """The KD-tree over feature columns ``cols`` (built on first use)."""
        key = cols.tobytes()
        if key not in self._trees:
            self._trees[key] = KDTree.build(self.features[:, cols])
        return self._trees[key]


def _padded(dims: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Part dims as a (P, 42) int64 array padded with zeros, and their counts (P,)."""
    out = np.zeros((len(dims), kernels.N_POSE), np.int64)
    for i, d in enumerate(dims):
        out[i, :len(d)] = d
    return out, np.array([len(d) for d in dims], np.int64)


@dataclass
class _History:
    """The temporal state: the last two solved poses and the last solved state."""

    n: int = 0                                   # poses in q1/q2 (0-2)
    q1: np.ndarray = field(default_factory=lambda: np.zeros((N_JOINTS, 3)))  # last pose
    q2: np.ndarray = field(default_factory=lambda: np.zeros((N_JOINTS, 3)))  # the one before
    m1: np.ndarray = field(default_factory=lambda: np.zeros((N_MARKERS, 3)))  # model markers of q1
    m2: np.ndarray = field(default_factory=lambda: np.zeros((N_MARKERS, 3)))  # and of q2
    has_state: bool = False
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    o: np.ndarray = field(default_factory=lambda: np.zeros(3))
    dirs: np.ndarray = field(default_factory=lambda: np.zeros((11, 3)))
    t_last: float = -np.inf   # time of the last solved or bridged frame
    t_seen: float = -np.inf   # time of the last frame with enough markers
    # the markers' last observations: bounds (8,) m, times (8,) s, positions (8, 3) m
    seen: tuple = field(default_factory=fresh_marker_state)


class Reconstructor:
    """Per-frame 8-marker -> 13-joint solver with state (temporal model, subject proportions).

    db: motion database (default: the shipped one); lengths: (8,) subject bone lengths in
    BONE_TYPES order, or None to estimate them from the first ``config.body_frames`` frames.
    offsets: (8, 3) marker offsets in their segment frames (samba_common.markerset), metres;
    None = markers on the joint centres. With ``lengths`` None and offsets given, the live body
    estimate removes the offsets first (the subject's offsets, or the typical ones). With both
    None the subject is measured live (``config.placement``; :mod:`.live_subject`): ``subject``
    holds the current one (None until the standard pose was seen) and ``subject_version``
    counts its changes. The joints solved are always joint centres; :meth:`markers_of` gives
    the model markers.
    """

    def __init__(self, db: MotionDB | None = None, config: ReconstructConfig | None = None,
                 lengths: np.ndarray | None = None, offsets: np.ndarray | None = None):
        self.db = db if db is not None else load_default_db()
        self.config = config or ReconstructConfig()
        self._given = (lengths, offsets)
        cfg = self.config
        rng = np.random.default_rng(cfg.seed)
        sigma = np.full(kernels.N_ANGLES, np.radians(cfg.ball_sigma_deg))
        sigma[7::3] = np.radians(cfg.hinge_sigma_deg)  # the third angle of each limb is its hinge
        angles = rng.standard_normal((cfg.pseudo, kernels.N_ANGLES)) * sigma  # fixed bank: deterministic
        self._cos, self._sin = np.cos(angles), np.sin(angles)
        self._floor2 = float(np.radians(cfg.prior_floor_deg) ** 2)
        self._dims = {flag: _padded(PART_DIMS if flag else (WHOLE[1],)) for flag in (False, True)}
        self._cols = {flag: _padded(PART_FEATURES if flag else WHOLE[:1]) for flag in (False, True)}
        self._estimating = lengths is None
        #: live subject: placement still to decide ("auto"), or fixed; None = the caller gave it
        self._live_placement = self.config.placement if lengths is None and offsets is None else None
        #: the live placement and why it was chosen ("skin (auto: standard pose ...)"), once decided
        self.placement_note: str | None = None
        self._next_offsets: np.ndarray | None = None
        self._calibration: LiveSubjectCalibration | None = None
        self.subject: Subject | None = None
        self.subject_version = 0
        self._body_buffer: list[np.ndarray] = []
        self._pending_body: tuple | None = None
        self.lengths: np.ndarray | None = None
        self.offsets = np.zeros((N_MARKERS, 3)) if offsets is None else np.array(offsets, dtype=float).reshape(N_MARKERS, 3)
        if not np.all(np.isfinite(self.offsets)):
            raise ValueError("marker offsets must be finite")
        self.index: PoseIndex | None = None
        self._hist = _History()
        if lengths is not None:
            self.set_lengths(lengths)
            self.subject = Subject(self.lengths, self.offsets, None, "skin" if np.any(self.offsets) else "joint_centres")

    def again(self, subject: Subject | None = None) -> "Reconstructor":
        """A new solver, without state, built as this one was (database, configuration, the
        subject given at construction), or for ``subject`` (its lengths and offsets) when given."""
        if subject is not None:
            return Reconstructor(self.db, self.config, subject.lengths, subject.offsets)
        return Reconstructor(self.db, self.config, *self._given)

    # --- subject -------------------------------------------------------------------------
    def set_lengths(self, lengths: np.ndarray) -> None:
        """Fix the subject's bone lengths (8,) metres and re-pose the database with them."""
        lengths = np.asarray(lengths, dtype=float)
        if lengths.shape != (len(BONE_TYPES),) or not np.all(np.isfinite(lengths)) or np.any(lengths <= 0):
            raise ValueError(f"bone lengths must be 8 positive numbers, got {lengths}")
        self.lengths, self.index, self._trees = self._build_index(lengths)

    def _build_index(self, lengths: np.ndarray, offsets: np.ndarray | None = None) -> tuple[np.ndarray, PoseIndex, tuple]:
        """The database re-posed with ``lengths`` and ``offsets`` (default: the current ones) and
        its KD-trees (lengths, index, tree arrays)."""
        index = PoseIndex(self.db, lengths, self.offsets if offsets is None else offsets)
        trees = tuple(index.tree(c).arrays() for c in (PART_FEATURES if self.config.parts else WHOLE[:1]))
        index.tree(WHOLE[0])  # for body_distance, built here (in the body worker thread when live)
        return lengths, index, trees

    def _set_subject(self, subject: Subject, built: tuple | None = None) -> None:
        """Install a live subject (and its re-posed index, else built now); logs it."""
        self.offsets = np.array(subject.offsets, float)
        self.lengths, self.index, self._trees = built if built is not None else self._build_index(subject.lengths)
        self.subject = subject
        self.subject_version += 1
        log.info("live subject #%d %s", self.subject_version, describe(subject))

    def warm_up(self) -> None:
        """Compile the solver and the labelling's database check (:meth:`body_distance`) now
        rather than on the first live frames (the very first run on a machine compiles for about
        a minute; later runs load the compiled code from disk; compiled on a live frame, the
        database check stalled the first demo for 2-9 s)."""
        lengths = self.lengths if self.lengths is not None else self.db.mean_lengths
        probe = Reconstructor(self.db, self.config, lengths, self.offsets)
        markers = markers_from_joints(standard_pose(lengths)[None], self.offsets)[0]
        for i in range(3):
            probe.solve(markers, i / 30.0)
        probe.body_distance(markers[None], 0.1)  # the labelling's check of names against the database

    def markers_of(self, joints: np.ndarray) -> np.ndarray:
        """Model markers (8, 3) (or (F, 8, 3)) of solved joints (13, 3) / (F, 13, 3): the joint
        centres plus this subject's offsets (what the labelling should predict)."""
        j = np.asarray(joints, dtype=float)
        single = j.ndim == 2
        m = markers_from_joints(j[None] if single else j, self.offsets)
        return m[0] if single else m

    def body_distance(self, markers: np.ndarray, within: float | np.ndarray = np.inf) -> np.ndarray:
        """How much like a body of this subject each marker set is: markers (H, 8, 3) world
        metres -> (H,) distance (metres, rms over the 8 markers and the up vector) from the
        set's aligned search feature to the nearest database pose re-posed for this subject (the
        motion database knows what bodies look like: a wrist named for its shoulder makes a
        pose no database body takes). NaN for sets with an unnamed marker, and for every set
        before the subject's body is known; inf for sets farther than within (metres, scalar or
        (H,)) from every pose. One KD-tree query per set: about 0.1 ms unbounded (an unseen
        subject's poses lie 5-15 cm from the nearest), a few microseconds with a tight bound."""
        m = np.asarray(markers, dtype=float).reshape(-1, N_MARKERS, 3)
        out = np.full(len(m), np.nan)
        ok = np.isfinite(m).all(axis=(1, 2))
        if self.index is None or not ok.any():
            return out
        feats = kernels.search_features(np.ascontiguousarray(m[ok]), UP_WEIGHT)
        within = np.broadcast_to(np.asarray(within, dtype=float), len(m))[ok]
        out[ok] = self.index.tree(WHOLE[0]).nearest_distance(feats, 3.0 * within) / 3.0
        return out

    def reset(self) -> None:
        """Forget the temporal history (a new take or a long gap); keeps the body."""
        self._hist = _History()

    # --- per frame -----------------------------------------------------------------------
    def solve(self, markers: np.ndarray, t: float, loose: np.ndarray | None = None) -> PoseResult:
        """Solve one frame. markers: (8, 3) world metres, NaN rows = unseen; t: seconds; loose:
        (8,) bool, markers whose position is rough (``sigma_loose`` instead of ``sigma_marker``;
        :meth:`~samba_server.labelling.Labeller.loose`), None = none."""
        markers = np.asarray(markers, dtype=float).reshape(N_MARKERS, 3)
        if self._estimating:
            self._estimate_body(markers)
            if self.lengths is None:
                return self._unsolved(int(np.all(np.isfinite(markers), axis=1).sum()))
        result = self._solve(markers, float(t), loose)
        if self._calibration is not None:
            self._calibration.step(markers, float(t), result.status, result.residual, result.state)
            if self._calibration.done:
                self._calibration = None
        return result

    def _decide_placement(self, buffer: np.ndarray) -> None:
        """Live, no subject given: skin landmarks or joint centres from the standard-pose frames
        (``config.placement`` "auto"), so that the body estimate removes the right offsets."""
        placement, why = self._live_placement, "given: --placement or [reconstruct] placement"
        if placement == "auto":
            found = placement_from_standard_pose(buffer, self.db.mean_lengths)
            if found is None:
                placement, why = "joint_centres", "auto: no standard pose in the first frames: joint centres assumed"
            else:
                placement, why, _n = found
                why = "auto: " + why
        self.placement_note = f"{placement.replace('_', ' ')} ({why})"
        log.info("live marker placement: %s", self.placement_note)
        self._live_placement = placement
        self._next_offsets = TYPICAL_OFFSETS.copy() if placement == "skin" else np.zeros((N_MARKERS, 3))

    def _estimate_body(self, markers: np.ndarray) -> None:
        """Live body estimate: from the first frame that shows enough of the body (built at once),
        then from the first ``body_frames`` frames (the standard pose), re-posed in a background
        thread and swapped in exactly ``body_frames`` frames later, so no frame waits for the
        rebuild and a replay swaps at the same frame as the live run."""
        n_cfg = self.config.body_frames
        self._body_buffer.append(markers)
        n = len(self._body_buffer)
        if self.lengths is None:
            try:
                self.set_lengths(estimate_lengths(np.array(self._body_buffer), self.db.mean_lengths, self.offsets))
            except ProportionError:
                return
            self._body_buffer = [markers]  # count the standard pose from the first usable frame
        elif n == n_cfg and self._pending_body is None:
            if self._live_placement is not None and self._next_offsets is None:
                self._decide_placement(np.array(self._body_buffer))
            offsets = self.offsets if self._next_offsets is None else self._next_offsets
            try:
                lengths = estimate_lengths(np.array(self._body_buffer), self.db.mean_lengths, offsets)
            except ProportionError:
                return
            box: dict = {}
            worker = threading.Thread(target=lambda: box.update(built=self._build_index(lengths, offsets)),
                                      daemon=True, name="samba-body")
            worker.start()
            self._pending_body = (worker, box)
        elif n >= 2 * n_cfg and self._pending_body is not None:
            worker, box = self._pending_body
            worker.join()
            self._estimating, self._body_buffer, self._pending_body = False, [], None
            if self._next_offsets is None:
                self.lengths, self.index, self._trees = box["built"]
                return
            skin = bool(np.any(self._next_offsets))
            lengths0 = box["built"][0]
            self._set_subject(Subject(lengths0, self._next_offsets, OFFSET_SIGMA.copy() if skin else None,
                                      "skin" if skin else "joint_centres"), box["built"])
            if skin:
                cfg = self.config
                self._calibration = LiveSubjectCalibration(
                    lengths0, (cfg.subject_seconds, cfg.subject_refine_seconds), cfg.subject_swap_frames,
                    self._build_index, self._set_subject)

    def _unsolved(self, n: int) -> PoseResult:
        return PoseResult(np.full((N_JOINTS, 3), np.nan), float("nan"), n, 0, "unsolved")

    def _solve(self, markers: np.ndarray, t: float, loose: np.ndarray | None = None) -> PoseResult:
        self._hist = self._current(self._hist, t)
        status, q, R, o, d, iters, resid, n_seen, mk = self._frame(markers, t, self._hist, loose)
        if status == 2:
            return PoseResult(q, float("nan"), int(n_seen), 0, "unsolved")
        h = self._hist
        mbounds, h.seen = marker_bounds(markers, mk, h.seen, t)
        bounds = joint_bounds(q, mbounds, self.novelty(markers, mk), self.lengths)
        h.q2, h.q1, h.n = h.q1, q, min(h.n + 1, 2)
        h.m2, h.m1 = h.m1, mk
        h.R, h.o, h.dirs, h.has_state, h.t_last = R, o, d, True, t
        if status == 0:
            h.t_seen = t
        return PoseResult(q, float(resid), int(n_seen), int(iters), "solved" if status == 0 else "bridged", (R, o, d),
                          bounds)

    def novelty(self, markers: np.ndarray, model: np.ndarray) -> float:
        """How unlike the database's bodies a frame's trunk and legs are: distance (m, over the
        knee and ankle coordinates in the marker body frame and the up vector) from the
        frame's search feature to the nearest database pose's. markers: (8, 3) observed (NaN
        rows unobserved, taken from model (8, 3), the solve's markers). NaN when unknown."""
        if self.index is None:
            return float("nan")
        filled = np.where(np.isfinite(markers), markers, model)
        if not np.isfinite(filled).all():
            return float("nan")
        feature = kernels.search_feature(np.ascontiguousarray(filled), UP_WEIGHT)[2]
        cols = PART_FEATURES[2]
        return float(self.index.tree(cols).nearest_distance(feature[cols])[0])

    def _current(self, h: _History, t: float) -> _History:
        """The temporal state h if it can still predict at t s, else a fresh one (a long gap
        forgets the history, as :meth:`reset`)."""
        return h if h.n == 0 or t - h.t_seen <= self.config.max_gap else _History()

    def _frame(self, markers: np.ndarray, t: float, h: _History, loose: np.ndarray | None = None) -> tuple:
        """The compiled per-frame solve (:func:`kernels.frame`) of markers (8, 3) at t s from the
        temporal state h, which it does not change, with the markers loose (8,) bool (None: none)
        at ``sigma_loose``; its outputs."""
        cfg = self.config
        sigma = np.full(N_MARKERS, cfg.sigma_marker)
        if loose is not None:
            sigma[np.asarray(loose, bool)] = cfg.sigma_loose
        assert self.lengths is not None and self.index is not None
        has_pred = h.n > 0 and t - h.t_seen <= cfg.max_gap
        trees = self._trees
        feat_cols, n_cols = self._cols[cfg.parts]
        dims, n_dims = self._dims[cfg.parts]
        return kernels.frame(
            markers, has_pred, h.n, h.q1, h.q2, h.m1, h.m2, h.has_state, h.R, h.o, h.dirs, t - h.t_last if h.n else 0.0,
            trees, self.index.features, feat_cols, n_cols, UP_WEIGHT, self.index.R_A, self.db.dirs, self.db.up,
            min(cfg.k, len(self.db)),
            dims, n_dims, self._cos, self._sin, self.lengths, self.offsets, self._floor2, cfg.prior_weight, sigma,
            cfg.accel, cfg.smooth_floor, cfg.min_markers, kernels.G, cfg.max_iter, cfg.tol)

    # --- trial solves (the labelling asks which names the solver can fit) ------------------
    def checkpoint(self) -> _History | None:
        """The temporal state, to try other names for the next frame from (:meth:`trial`) and
        to go back to (:meth:`restore`); None while the subject is still being measured (the
        frame's markers also feed that measurement, which a second solve would repeat)."""
        if self.lengths is None or self._estimating or self._calibration is not None:
            return None
        h = self._hist
        return _History(h.n, h.q1.copy(), h.q2.copy(), h.m1.copy(), h.m2.copy(), h.has_state, h.R.copy(),
                        h.o.copy(), h.dirs.copy(), h.t_last, h.t_seen, h.seen)

    def restore(self, state: _History) -> None:
        """Go back to a :meth:`checkpoint` (to solve the frame again with other names)."""
        self._hist = state

    def trial(self, markers: np.ndarray, t: float, state: _History) -> float:
        """rms marker residual (m) of solving markers (8, 3) at t s from ``state`` (a
        :meth:`checkpoint`), changing nothing; NaN when it would not solve or only bridge."""
        status, *_rest, resid, _n, _mk = self._frame(np.asarray(markers, float), float(t), self._current(state, t))
        return float(resid) if status == 0 else float("nan")


def solve_frames(rec: Reconstructor, markers: np.ndarray, t: np.ndarray, order, progress=None,
                 loose: np.ndarray | None = None) -> list[PoseResult]:
    """``rec.solve`` over the frames in ``order`` (indices into markers (F, 8, 3) and t (F,) s;
    backwards in time with t negated): a PoseResult per frame, by frame index. A solver error
    is logged and leaves the frame unsolved. progress: optional callable(1) per frame; loose:
    optional (F, 8) bool, the markers of each frame whose position is rough."""
    out: list[PoseResult] = [None] * len(t)  # type: ignore[list-item]
    for i in order:
        try:
            out[i] = rec.solve(markers[i], float(t[i]), None if loose is None else loose[i])
        except Exception:
            log.exception("solver failed on frame t=%.3f s (frame left unsolved)", abs(float(t[i])))
            out[i] = PoseResult(np.full((N_JOINTS, 3), np.nan), float("nan"), 0, 0, "unsolved")
        if progress is not None:
            progress(1)
    return out


#: per limb bone (kernels' bone order), the markers (MARKER_NAMES order) that place its limb
_LIMB_MARKERS = {kernels.LUA: [0, 2], kernels.LFA: [0, 2], kernels.RUA: [1, 3], kernels.RFA: [1, 3],
                 kernels.LTH: [4, 6], kernels.LSH: [4, 6], kernels.RTH: [5, 7], kernels.RSH: [5, 7]}


def _merge(a: PoseResult, b: PoseResult, lengths: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Joints (13, 3) of the mean of two solved states: the torso rotations' chordal mean, and
    each bone's world direction averaged (weight w (11,) for a's) and expressed in that torso
    frame, so the merged pose keeps the subject's bone lengths exactly."""
    Ra, oa, da = a.state  # type: ignore[misc]
    Rb, ob, db = b.state  # type: ignore[misc]
    U, _s, Vt = np.linalg.svd(Ra + Rb)
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    # mean of the bones' world directions (the two passes may share a world pose yet split it
    # differently between torso rotation and bone directions), back in the mean torso frame
    u = w[:, None] * (da @ Ra.T) + (1.0 - w[:, None]) * (db @ Rb.T)
    d = u @ R
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[2, 2] = 0.0  # the spine stays in the torso's x-y plane
    d[2] /= np.linalg.norm(d[2])
    return fk(0.5 * (oa + ob), R, d, lengths)


def _frames_since(seen: np.ndarray) -> np.ndarray:
    """(F, 8) frames since each marker was last seen (0 where seen, inf before its first), from
    seen (F, 8) bool."""
    out = np.empty(seen.shape)
    last = np.full(seen.shape[1], -np.inf)
    for i, row in enumerate(seen):
        last[row] = i
        out[i] = i - last
    return out


def _gap_weights(markers: np.ndarray) -> np.ndarray:
    """(F, 11) weight of the forward pass's direction of each bone: a limb whose markers were
    hidden is trusted to the pass that saw them last more recently (frames since they were last
    seen going forwards, gf, and until they are seen again, gb: weight gb / (gf + gb); 0.5 where
    both passes see them, and for the trunk's bones)."""
    seen = np.isfinite(markers).all(axis=2)  # (F, 8)
    gf, gb = _frames_since(seen), _frames_since(seen[::-1])[::-1]
    w = np.full((len(seen), 11), 0.5)
    for bone, ms in _LIMB_MARKERS.items():
        f, b = gf[:, ms].max(axis=1), gb[:, ms].max(axis=1)  # 0, 0 where every marker is seen
        gap = (f > 0) & np.isfinite(f) & np.isfinite(b)
        w[gap, bone] = b[gap] / (f[gap] + b[gap])
        w[np.isinf(b) & np.isfinite(f), bone] = 1.0  # never seen again: the forward pass saw it last
        w[np.isinf(f) & np.isfinite(b), bone] = 0.0  # not seen yet: the backward pass saw it first
    return w


#: a merged pose whose marker joints lie this much (m) farther from the observed markers than
#: one pass's is not used (the bone directions' mean of two elbow swivels misses a wrist by 2-5
#: cm: kept, it halves the elbow's error; 2 cm made more hidden joints > 20 cm off on dribbles)
MERGE_FIT_M = 0.05


def _marker_misfit(joints: np.ndarray, markers: np.ndarray, offsets: np.ndarray | None) -> float:
    """Largest distance (m) between the model markers of joints (13, 3) (the joint centres plus
    the subject's offsets (8, 3), None = joint centres) and the observed markers (8, 3) (NaN rows
    unobserved); 0 when none is observed."""
    e = np.linalg.norm(markers_from_joints(joints[None], offsets)[0] - markers, axis=1)
    e = e[np.isfinite(e)]
    return float(e.max()) if e.size else 0.0


def _fitting(merged: np.ndarray, ja: np.ndarray, jb: np.ndarray, markers: np.ndarray,
             offsets: np.ndarray | None) -> np.ndarray:
    """The merged pose (13, 3), or the pass's pose (ja or jb, 13, 3) that fits the observed
    markers (8, 3) better when the merge moved a model marker (offsets: see
    :func:`_marker_misfit`) ``MERGE_FIT_M`` farther off than that pass had it. Two passes that
    fit the same markers but split the pose differently (the hips of a climber 30 cm apart)
    average to directions that fit neither: a knee 18 cm from its marker, under the 3 cm bound
    each pass gave it."""
    fa, fb = _marker_misfit(ja, markers, offsets), _marker_misfit(jb, markers, offsets)
    if _marker_misfit(merged, markers, offsets) <= min(fa, fb) + MERGE_FIT_M:
        return merged
    return ja if fa <= fb else jb


def _bounds_at(joints: np.ndarray, a: PoseResult, b: PoseResult) -> np.ndarray:
    """Bounds (13,) m of joints (13, 3) made from two solved passes a and b: either pass's
    bound plus how far the joint is from that pass's (the truth within a pass's bound of its
    joint is within that much more of this one), the larger of the two (either pass may be
    the one whose bound fails)."""
    da = np.linalg.norm(joints - a.joints, axis=1)
    db = np.linalg.norm(joints - b.joints, axis=1)
    return np.maximum(a.bounds + da, b.bounds + db)


def merge_passes(fwd: list[PoseResult], bwd: list[PoseResult], lengths: np.ndarray, markers: np.ndarray | None = None,
                 offsets: np.ndarray | None = None) -> tuple[np.ndarray, list[PoseResult]]:
    """Merge a forward and a backward solve of the same F frames: ((F, 13, 3) joints, the
    PoseResult kept per frame). Where both passes solved a frame from its markers, the mean of
    their states (:func:`_merge`, bone lengths ``lengths`` (8,) m); where only the backward pass
    did, its pose; elsewhere the forward pass's (its bridges included). A backward bridge is
    never used: it would invent poses up to ``max_gap`` before the markers come back, i.e. deep
    into a blackout, where the forward bridge is already as far as a guess may go. markers:
    the (F, 8, 3) markers both passes solved (NaN = unseen), to take a hidden limb more from the
    pass that saw it more recently (:func:`_gap_weights`; None: equal weights) and to keep a
    pass's pose where the merge fits them worse (:func:`_fitting`; offsets (8, 3) the subject's
    marker offsets, None = joint centres). A merged frame's joint bounds cover both passes'
    (:func:`_bounds_at`)."""
    F = len(fwd)
    joints = np.array([r.joints for r in fwd], float).reshape(F, N_JOINTS, 3)
    results = list(fwd)
    w = _gap_weights(markers) if markers is not None else np.full((F, 11), 0.5)
    for i, (a, b) in enumerate(zip(fwd, bwd)):
        if b.status != "solved":
            continue
        if a.status == "solved" and a.state is not None and b.state is not None:
            merged = _merge(a, b, lengths, w[i])
            if markers is not None:
                merged = _fitting(merged, a.joints, b.joints, markers[i], offsets)
            joints[i] = merged
            results[i] = replace(a, bounds=_bounds_at(merged, a, b))
        elif a.status != "solved":
            joints[i], results[i] = b.joints, b
    return joints, results


def solve_both_ways(rec: Reconstructor, markers: np.ndarray, t: np.ndarray, progress=None,
                    loose: np.ndarray | None = None) -> tuple[np.ndarray, list[PoseResult]]:
    """Solve markers (F, 8, 3) at t (F,) s forwards with ``rec`` (fresh: exactly as live), then
    backwards in time with a solver for the subject it has (measured from the standard pose,
    or given), and merge the two per frame (:func:`merge_passes`): the temporal model sees the
    future too. Forwards only when rec has no subject or F < 2. Returns ((F, 13, 3) joints, the
    PoseResult kept per frame). progress: optional callable(1) per solve; loose: optional
    (F, 8) bool, the markers whose position is rough (:meth:`Reconstructor.solve`)."""
    F = len(t)
    fwd = solve_frames(rec, markers, t, range(F), progress, loose)
    if rec.subject is None or F < 2:
        return np.array([r.joints for r in fwd], float).reshape(F, N_JOINTS, 3), fwd
    # time runs backwards: feed -t so the solver sees increasing times
    bwd = solve_frames(rec.again(rec.subject), markers, -np.asarray(t, float), range(F - 1, -1, -1), progress, loose)
    return merge_passes(fwd, bwd, rec.lengths, markers, rec.offsets)


def reconstruct_take(markers: np.ndarray, t: np.ndarray, db: MotionDB | None = None,
                     config: ReconstructConfig | None = None, lengths: np.ndarray | None = None,
                     progress=None, both_ways: bool = True,
                     offsets: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """Reconstruct a whole take offline.

    markers: (F, 8, 3) world metres, NaN = unseen; t: (F,) seconds. lengths: subject bone lengths
    (8,), default: estimated from the whole take. progress: optional callable(n_frames_done).
    both_ways: solve the take forwards (exactly as live) and backwards in time and merge the two
    states per frame (the temporal model then sees the future too); False gives exactly the
    live poses. offsets: (8, 3) marker offsets in segment frames (None: joint centres); the
    joints returned are joint centres either way.
    Returns joints (F, 13, 3) (NaN frames where unsolved) and an info dict with per-frame
    ``residual`` (F,), ``n_markers`` (F,), ``iterations`` (F,), ``status`` (F,), ``joint_bound``
    (F, 13) m (how far each joint may be off, :mod:`.bounds`) and the
    ``lengths`` (8,), ``ms_per_frame`` (per solve).
    """
    db = db if db is not None else load_default_db()
    if lengths is None:
        lengths = estimate_lengths(markers, db.mean_lengths, offsets)
    lengths = np.asarray(lengths, float)
    F = len(t)
    t0 = time.perf_counter()
    rec = Reconstructor(db, config, lengths, offsets)
    if both_ways:
        joints, results = solve_both_ways(rec, markers, t, progress)
    else:
        results = solve_frames(rec, markers, t, range(F), progress)
        joints = np.array([r.joints for r in results], float).reshape(F, N_JOINTS, 3)
    n_solves = 2 * F if both_ways and F > 1 else F
    elapsed = time.perf_counter() - t0
    info = {"residual": np.array([r.residual for r in results]),
            "n_markers": np.array([r.n_markers for r in results], np.int16),
            "iterations": np.array([r.iterations for r in results], np.int16),
            "status": np.array([r.status for r in results], dtype="<U8"),
            "joint_bound": np.array([r.bounds for r in results], float).reshape(F, N_JOINTS),
            "lengths": lengths, "ms_per_frame": 1e3 * elapsed / max(n_solves, 1),
            "offsets": np.zeros((N_MARKERS, 3)) if offsets is None else np.asarray(offsets, float)}
    return joints, info
