"""The labelling stage of the server: packets of one frame -> the 8 named 3D markers.

:class:`Labeller` keeps one track per marker (position, velocity, when last seen). Per frame:

1. unlabelled 3D points from every view's blobs (:mod:`.points`);
2. **tracking**: each marker is predicted (its track at constant velocity while it was seen
   recently, else the reconstructed skeleton's joint, which the solver keeps moving with the
   body) and the points are named by an optimal assignment (Hungarian) of points to predicted
   markers within a gate that grows with the time since the marker was seen. The motes' labels
   lower the cost of agreeing assignments a little: evidence, not orders. A knee and the other
   leg's ankle parting from one merged point take each other's point when that fits the shins
   clearly better; crossed legs are swapped back; assignments that break a rigid distance of the
   subject (:mod:`.rigid`) or turn the facing faster than a body turns are dropped; markers
   left out are recovered from the free points where their prediction or the rigid lengths put
   them, when the choice is clear;
3. **identification** (:mod:`.identify`) when fewer than ``min_tracked`` markers can be
   predicted (the start of a take, after a blackout or once the subject left the volume), or
   when tracking explains too few of the points for ``lost_after`` s (a jump): the points are
   named from scratch: at once when the best labelling's margin is clear, else the markers the
   close runner-ups agree on, else (no shoulders) after ``max_wait`` s the best one.

Every frame gets a :class:`LabelQuality`. All decisions depend only on the frame's packets,
its time and what the server fed back (solved joints, body lengths), so a replay gives the
live labels exactly.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from samba_common.body import ANKLE_HEIGHT
from samba_common.calib import CameraRig
from samba_common.skeleton import MARKER_JOINT, N_MARKERS

from ..triangulate import Triangulator
from .blobs import median_rows, view_blobs
from .blobs import warm_up as warm_up_blobs
from .clutter import StillBlobs, on_clutter
from .clutter import warm_up as warm_up_clutter
from .elongation import blob_separation, jacobians, separation_3d
from .identify import ANKLE_ABOVE_M, Hint, Hypothesis, identify, right_of, score_labels, sized
from .points import PointReconstructor, Points3D, PointsConfig, blob_votes
from .rigid import LA, LEVEL_M, LK, LS, LW, RA, RK, RS, RW, SIDES, Body

log = logging.getLogger(__name__)

__all__ = ["LabelConfig", "LabelQuality", "LabelStats", "Labeller"]


def _unnamed(n: int, assign: np.ndarray) -> np.ndarray:
    """The points (of n) no marker is named after, sorted: ``np.setdiff1d(np.arange(n),
    assign[assign >= 0])`` for assign (8,) (point per marker, -1 = none), without its sorting."""
    named = np.zeros(n, bool)
    named[assign[assign >= 0]] = True
    return np.flatnonzero(~named)


def _named_on(pts: Points3D, assign: np.ndarray) -> np.ndarray:
    """(8, 3) m: each marker at the point assign (8,) names it on (-1: NaN, unnamed)."""
    out = np.full((N_MARKERS, 3), np.nan)
    out[assign >= 0] = pts.X[assign[assign >= 0]]
    return out


def _recoverable(pts: Points3D, assign: np.ndarray) -> np.ndarray:
    """The points no marker is named on (assign (8,), -1 = none) that a lost marker may be
    found again on: seen by >= 3 views, or missed by at most one view that should see them."""
    free = _unnamed(len(pts), assign)
    return free[(pts.n_views[free] >= 3) | (pts.unexplained[free] <= 1)]


@dataclass(frozen=True)
class LabelConfig:
    """``[labelling]`` in configs/server.toml (distances in metres, times in seconds)."""

    gate_m: float = 0.10  #: largest distance between a point and its marker's prediction, just after it was seen
    gate_growth: float = 1.5  #: m/s: the gate grows with the time since the marker was seen ...
    max_gate_m: float = 0.30  #: ... up to this
    skeleton_gate_m: float = 0.15  #: gate around a prediction taken from the reconstructed skeleton
    hint_m: float = 0.01  #: a view whose mote gave the same label lowers the cost by this
    merged_m: float = 0.02  #: a point seen in a merged blob costs this much more
    unexplained_m: float = 0.03  #: a 2-view point costs this much more per view that should have seen it
    merged_half_m: float = 0.08  #: two markers in one merged point lie at most this far either side of it (the guess; see split_sigma_px)
    split_sigma_px: float = float("inf")  #: noise of the separation a merged blob's moments measure, to split two markers on one point by it, but the knees, the ankles or the wrists (inf: off, the default: see docs/labelling.md; 0.5 on the simulator's blobs)
    split_legs_sigma_px: float = 0.5  #: the same for the two knees or the two ankles (inf: off; on by default: the hip width the subject is measured with comes from them) ...
    split_wrists_sigma_px: float = 0.5  #: the same for the two wrists (hands together), the sign from their tracks' separation (inf: off)
    split_legs_max_deg: float = 35.0  #: ... used only this close in direction to the guess (the subject's right): further off, the guess cannot tell which end is which
    split_in_line_m: float = 0.06  #: two knees or ankles on one point, named the frame before at least this far apart more than split_legs_max_deg off the subject's right (one before the other), uncrossed, are placed along that separation (inf: never)
    split_share_s: float = 0.1  #: a knee and the other leg's ankle on one point are placed either side of it along their predictions for this long, then both on it (inf: always split)
    split_prior_m: float = 0.10  #: how far (per axis) the measured separation may differ from the guess without moments
    split_min_views: int = 3  #: merged views needed to measure it (one says nothing along its ray)
    rescue_m: float = 0.06  #: a tracked marker with no point (a leg only while the legs' names are sure) is triangulated from two views' blobs within this of its prediction (0: never) ...
    rescue_px: float = 0.3  #: ... that meet within this (rms reprojection error, px) ...
    rescue_max_s: float = 1.0  #: ... for at most this long after it was last named on a point
    rescue_growth: float = 0.5  #: ... rescue_m growing by this (m/s) with the time since the marker was last named
    recover_gate_m: float = 0.45  #: a marker left out may take a free, sure point this far from its prediction ...
    recover_margin_m: float = 0.10  #: ... when the best assignment without that pair costs this much more
    recover_speed: float = 6.0  #: ... a shoulder or wrist within gate_m + this (m/s) x its time unnamed (inf: no limit)
    wrist_side_w: float = 0.5  #: m of cost per m a wrist not named last frame is nearer the other shoulder than its own
    glued_wrist_s: float = 0.3  #: a wrist held a shoulder width from the other shoulder this long, its own shoulder unnamed, is that shoulder
    anchor_m: float = 0.05  #: cost of a point placed by the rigid lengths rather than the prediction
    shins_margin_m: float = 0.04  #: both ankles (or knees) unnamed, the other two named: named on the two free points that fit the shins this much better (m, both summed) than any other pairing (inf: never)
    wrist_clear_m: float = 0.15  #: a lost wrist found within its arm's reach must be this far from every named marker
    apart_views: int = 2  #: both wrists named, neither seen apart from the other in this many views (hands together): the poses carry them unnamed, a gap rather than a coin flip, still solved from them (0: never; :meth:`Labeller.unseparated`)
    together_m: float = 0.3  #: ... but not wrists named farther apart (m) on points within the points stage's rough_px, no blob shared: no track confuses them (inf: never)
    max_turn_rate: float = 12.0  #: rad/s: the facing may turn this fast ...
    turn_slack_deg: float = 45.0  #: ... plus this much (noise of the shoulder points) between labellings
    crossed_m: float = 0.06  #: a right knee or ankle this far left of the left one is taken for a swap
    split_crossed_m: float = 0.03  #: knees or ankles named crossed by this much in the frame before, placed uncrossed either side of their merged point, are reported renamed (:meth:`_split_shared`)
    crossed_memory_s: float = 2.0  #: a pair named crossed this little before the names were lost may be crossed again
    knees_crossed_s: float = 1.0  #: knees crossed (by crossed_m) this long are the legs' names swapped (inf: never)
    legs_sure_m: float = 0.08  #: legs named afresh are unsure (:attr:`Labeller.legs_unsure`) until the knees are named this far apart along the subject's right, the left one on the left (inf: always unsure)
    arm_swap_s: float = 0.05  #: a shoulder off the shoulder width whose own wrist's point fits it this long swaps with that wrist (inf: never)
    reach_swap_m: float = 0.02  #: the wrists swap names when one is this far beyond its arm's reach from its shoulder ... (inf: never)
    reach_fit_m: float = 0.03  #: ... and swapped both are this far within it
    shin_swap_min: float = 0.5  #: a leg pair is swapped when that mends a broken shin and the other shin is broken by at least this share of the tolerance (inf: never) ...
    shin_mend_max: float = 0.5  #: ... or when one shin is broken and the swap fits both within this share of it (0: never)
    cross_gain_m: float = 0.04  #: legs named side by side whose shins fit this much better (m, both summed) with the feet crossed ...
    cross_fit: float = 0.5  #: ... both within this share of the tolerance ...
    cross_s: float = 0.1  #: ... for this long are named crossed (inf: never)
    fit_swap_ratio: float = 0.6  #: names swapped when that brings the 8 markers this much nearer (ratio) a database pose ...
    fit_swap_s: float = 0.05  #: ... the same swap at every check for this long (inf: never) ...
    fit_interval: float = 0.05  #: ... checked this often (s; 0: every frame)
    fit_mirror_s: float = 1.5  #: ... the mirror image (all names left for right) only this long after an identification (inf: always; always with 2 cameras)
    refit_residual_m: float = 0.04  #: names the solver fits no better than this (rms m) are doubted ...
    refit_ratio: float = 0.25  #: ... and swapped when the swap lets it fit them this much better (ratio) ...
    refit_s: float = 0.05  #: ... the same swap for this long (inf: never)
    rough_jump_m: float = 0.10  #: a rough 2-view point two views miss is no place for a marker farther than this from its prediction
    track_timeout: float = 0.12  #: a marker unseen for longer is predicted from the skeleton
    skeleton_max_age: float = 0.4  #: the skeleton predicts markers up to this long after the last solved pose
    min_tracked: int = 3  #: fewer predictable markers: identify from the points
    lost_after: float = 0.3  #: this long with most points unexplained: identify again
    min_points: int = 4  #: points needed to identify
    min_margin: float = 0.6  #: an identification this much better than the runner-up is taken at once
    max_wait: float = 0.2  #: else the best one is taken after this long ...
    steady_s: float = 0.05  #: ... or, with >= 3 cameras, once it has named the same markers at the same places (gate_m) this long (inf: never)
    audit_interval: float = 0.1  #: s: while tracking leaves a sure point unnamed, identify afresh this often (inf: never) ...
    audit_margin: float = 1.0  #: ... and take the identification when it scores this much more than the tracked names
    audit_agree: float = 0.3  #: score, per marker, of agreeing with a tracked name in that identification (or with where it was last named: recall_m)
    audit_extend_margin: float = 0.5  #: an identification that only adds names to the tracked ones needs this much more
    audit_move_margin: float = 2.0  #: ... and one that moves >= 2 tracked names to other points, naming < 2 more, this much ...
    audit_fit_m: float = 0.01  #: ... and never while the solver fits the tracked names within this (rms m; >= 3 cameras; 0: by score alone)
    audit_shoulder_s: float = 0.05  #: tracked names lacking a shoulder are audited only once it has been unnamed this long (>= 3 cameras)
    audit_shoulder_lost_s: float = 0.5  #: ... and this long, a clear identification naming both shoulders and as many markers replaces them
    facing_weight: float = 3.0  #: weight of the known facing when identifying ...
    facing_decay: float = 1.0  #: ... decaying with this time constant since it was known ...
    facing_turn_rate: float = 1.5  #: ... and free within this many rad/s since then (at most 90 degrees)
    first_facing: tuple[float, float] = (0.0, 1.0)  #: before any labelling the subject faces this way (x, y): the standard pose's +Y ...
    first_facing_weight: float = 1.0  #: ... with this weight
    recall_m: float = 0.10  #: identifying afresh, a point this close to where a marker was last named ... (0: never)
    recall_s: float = 2.0  #: ... at most this long ago counts as that marker (audit_agree): a subject still through a blackout (>= 3 cameras)
    time_reversed: bool = False  #: the take is labelled backwards in time (samba-process's second pass): the body travels the other way
    part_s: float = 0.3  #: a knee and the other leg's ankle that shared a merged point this recently and now part ...
    part_gain_m: float = 0.03  #: ... swap points when the shins fit this much better (m, both summed; inf: never)
    rigid_abs_tol: float = 0.05  #: rigid distances may differ by this ...
    rigid_rel_tol: float = 0.03  #: ... plus this fraction of half the body height
    points: PointsConfig = field(default_factory=PointsConfig)


@dataclass
class LabelQuality:
    """How sure the labels of one frame are.

    n_labelled: markers named; n_points: 3D points found; margin_m: the smallest gap between a
    named marker's assignment cost and its runner-up's (metres; identification margins are
    converted at 0.1 m per score unit); residual_m: rms distance between named markers and
    their predictions; mode: "tracking", "identified" or "lost"; overridden: named markers
    whose blob a mote had labelled otherwise; renamed: bit m set when marker m's name, held
    until the frame before, was found wrong in this one and replaced (a swap rule, an audit, an
    identification, or two knees or ankles named crossed and now placed uncrossed either side
    of their merged point), 0 when none was.
    """

    n_labelled: int = 0
    n_points: int = 0
    margin_m: float = float("nan")
    residual_m: float = float("nan")
    mode: str = "lost"
    overridden: int = 0
    renamed: int = 0


@dataclass
class LabelStats:
    """Counters of one run: frames, frames with >= 2 points, identifications (first and
    re-acquisitions), overridden mote labels, each re-acquisition's delay (s) from the
    first frame with points after the labels were lost to the frame they came back, audits of
    the tracked names by a fresh identification and how many of them replaced the names, frames
    whose names replaced wrong ones (:attr:`LabelQuality.renamed`), names swapped because the
    solver could fit them only so (:meth:`Labeller.refit`)."""

    frames: int = 0
    frames_with_points: int = 0
    identifications: int = 0
    overridden: int = 0
    reacquire_s: list[float] = field(default_factory=list)
    first_identified_t: float | None = None
    audits: int = 0
    audit_switches: int = 0
    renames: int = 0
    refits: int = 0


class Labeller:
    """See the module docstring. rig: the calibration; triangulator: the server's (shares its
    undistortion tables); prior_lengths: (8,) bone lengths (BONE_TYPES order, m) expected
    before the subject is measured, e.g. the motion database's mean body (None: an average
    adult)."""

    def __init__(self, rig: CameraRig, triangulator: Triangulator | None = None, config: LabelConfig | None = None,
                 prior_lengths: np.ndarray | None = None):
        self.rig = rig
        self.config = config or LabelConfig()
        self.points = PointReconstructor(rig, triangulator or Triangulator(rig), self.config.points)
        self.still = StillBlobs(self.config.points.still_s, self.config.points.still_px)  #: static reflections learnt
        warm_up_blobs()
        warm_up_clutter()
        self.stats = LabelStats()
        # the prior body (database mean); _body is the body the rules use: the prior at the size of the
        # first identification's shoulders, then the measured subject. With two cameras every point
        # is a 2-view point, ghosts at any height among them: the prior keeps its size (stand 0)
        # until measured (a dribble scaled to ghost shoulders: 61 -> 46 % of frames right)
        self._prior = self._body = Body.from_lengths(prior_lengths, self.config.rigid_abs_tol,
                                                     self.config.rigid_rel_tol, measured=False)
        if len(rig) < 3:
            self._prior = self._body = replace(self._body, stand=0.0)
        self._lengths_key: bytes | None = None
        self._pos = np.full((N_MARKERS, 3), np.nan)
        self._vel = np.zeros((N_MARKERS, 3))
        self._seen = np.full(N_MARKERS, -np.inf)
        self._skel: list[tuple[float, np.ndarray]] = []
        self._fit = (-math.inf, math.nan)  # (t s, rms residual m) of the last solved pose
        self._facing: np.ndarray | None = None
        self._t_facing = -np.inf
        self._centres: list[tuple[float, np.ndarray]] = []
        self._t_good = -np.inf          # last frame where tracking explained the points
        self._named_last = False        # the frame before had a name
        self._renamed = 0               # bit m: marker m's name replaced as wrong this frame (LabelQuality.renamed)
        #: the quality of the last frame labelled
        self.last_quality = LabelQuality()
        self._t_lost: float | None = None  # first frame with points after the labels were lost
        self._t_ambiguous: float | None = None
        #: (since, last frame's time, (8, 3) markers) of an unclear identification's best labelling
        self._steady: tuple[float, float, np.ndarray] | None = None
        #: (time, (8, 3) markers) of the last identification's best labelling
        self._best_prev: tuple[float, np.ndarray] | None = None
        self._shared = np.zeros(N_MARKERS, bool)
        self._named_prev: tuple[np.ndarray, Points3D | None] = (np.full((N_MARKERS, 3), np.nan), None)  # the frame before's names and points
        self._lined: set[tuple[int, int]] = set()  # leg pairs split one before the other (_in_line) this frame
        self._lined_prev: set[tuple[int, int]] = set()  # ... and the frame before
        self._together: dict[tuple[int, int], float] = {}  # (m, n) markers -> when they last shared a point
        self._sharing: dict[tuple[int, int], float] = {}  # a knee and the other ankle -> since when they share a point
        self._sharing_t = -np.inf  # the frame _sharing was last updated in
        self._views: list = []  # this frame's blobs per camera (ViewBlobs)
        self._clutter: list[np.ndarray] = []  # this frame's static reflections per camera ((N,) bool per view)
        self._pts: Points3D | None = None  # this frame's 3D points
        self._knees_crossed_since: float | None = None
        self._legs_unsure = False  # the legs' names may be each other's (legs_unsure)
        self._cross_since: float | None = None  # since when the shins fit clearly better crossed
        self._cross_seen = -np.inf  # when the crossed-feet check could last be made
        self._arm_swap_since: list[float | None] = [None, None]  # per side: since when its wrist fits the shoulder better
        self._fit_swap: tuple[int, float] | None = None  # (row of _FIT_SWAPS, since when) that makes the names fit a body better
        self._t_fit = -np.inf  # last database-fit check
        self._t_identified = -np.inf  # when the names were last identified afresh
        self._refit: tuple[int, float] | None = None  # (row of _FIT_SWAPS, since when) the solver fits far better
        #: (H, 8, 3) marker sets [, within] -> (H,) distance to the nearest body the motion
        #: database knows, inf beyond within (:meth:`Reconstructor.body_distance`; the server
        #: sets it), or None
        self.pose_fit: Callable[..., np.ndarray] | None = None
        self._t_audit = -np.inf
        self._t_frame = self._t_prev = -np.inf  # this frame's and the previous frame's times
        self._free_hist: list[tuple[float, np.ndarray]] = []  # (t, free sure points (F, 3)) over the last second
        self._glue: tuple[list, list] = ([], [])  # per shoulder: (t, wrist-to-other-shoulder m, height difference m, wrist)
        self._on_point = np.full(N_MARKERS, -np.inf)  # per marker: when it was last named on a point (not rescued)
        self._rescued = np.zeros(N_MARKERS, bool)  # this frame's markers found by :meth:`_rescue`
        # this frame's rescues: (X (3,) m, blob per view (C,))
        self._rescue_blobs: list[tuple[np.ndarray, np.ndarray]] = []

    # ------------------------------------------------------------------ feedback from the server
    def observe(self, t: float, joints: np.ndarray, residual: float = math.nan) -> None:
        """Remember a solved pose: t seconds, joints (13, 3) metres (NaN frames are ignored),
        residual: its rms marker error (m), how well a body fits the names given."""
        if np.all(np.isfinite(joints)):
            self._skel = (self._skel + [(t, joints[list(MARKER_JOINT)].copy())])[-2:]
            self._fit = (t, float(residual))

    def refit(self, markers: np.ndarray, model: np.ndarray, residual: float, t: float,
              trial: Callable[[np.ndarray], float]) -> np.ndarray | None:
        """The solver's verdict on the names just given: markers (8, 3) as :meth:`label` named
        them at t s (NaN = unnamed), model (8, 3) the solved pose's markers, residual its rms
        marker error (m). Names no body fits (residual > ``refit_residual_m``; a dancer's kick
        lifts the ankle above the knee, the knee's point was hidden for a frame and the two names
        came back the other way round: 11-17 cm rms for 0.7 s, and no database body is near the
        kick to tell) are tried swapped as :meth:`_swap_to_fit` would (each confusion tracking
        can make that moves a marker the pose misses by more than that; with a marker left
        unnamed, the name moves to it), solved by ``trial``
        ((8, 3) markers -> rms residual m, from the solver's state before this frame). A swap
        the solver fits ``refit_ratio`` as badly, the same one for ``refit_s``, is made: names
        and tracks. Returns the renamed markers (8, 3), or None (names kept)."""
        cfg = self.config
        named = np.isfinite(markers).all(axis=1)
        if not residual > cfg.refit_residual_m or not math.isfinite(cfg.refit_s):
            self._refit = None
            return None
        off = named & (np.linalg.norm(model - markers, axis=1) > cfg.refit_residual_m)
        # a name given to another marker's point whose own name is unnamed moves there (a
        # dancer's left knee, hidden, named on the point of the kicking ankle above it: 7-12 cm
        # rms for 0.2 s, 1-2 cm with the ankle's name; the mirror image only as _swappable says)
        moves = (_FIT_MOVES & ~named).any(axis=1)
        moves[[_MIRROR, _UPPER_MIRROR]] = False
        rows = np.flatnonzero((self._swappable(named, t) | moves) & (_FIT_MOVES & off).any(axis=1))
        fits = np.array([trial(markers[_FIT_SWAPS[r]]) for r in rows])
        ok = np.isfinite(fits) & (fits < cfg.refit_ratio * residual)
        if not ok.any():
            self._refit = None
            return None
        best = int(rows[np.argmin(np.where(ok, fits, np.inf))])
        if self._refit is None or self._refit[0] != best:
            self._refit = (best, t)
        if t - self._refit[1] < cfg.refit_s - 1e-6:
            return None
        perm = _FIT_SWAPS[best]
        pairs = [(m, int(perm[m])) for m in range(N_MARKERS) if perm[m] > m]
        log.debug("t=%.3f s: names %s swapped: the solver fits them %.3f m rms, %.3f as they were", t, pairs,
                  float(np.nanmin(fits)), residual)
        self._refit = None
        out = markers.copy()
        self._renamed = 0
        self._swap(pairs, out)
        self.stats.renames += int(self.last_quality.renamed == 0)
        self.last_quality.renamed |= self._renamed
        self.stats.refits += 1
        return out

    def set_lengths(self, lengths: np.ndarray | None, offsets: np.ndarray | None = None) -> None:
        """The subject's bone lengths (8,) (BONE_TYPES order) once measured, and its markers'
        offsets (8, 3) m from their joint centres (None: on them); None lengths keep the
        default body."""
        if lengths is None:
            return
        key = np.asarray(lengths, float).tobytes() + (b"" if offsets is None else np.asarray(offsets, float).tobytes())
        if key != self._lengths_key:
            self._lengths_key = key
            self._body = Body.from_lengths(lengths, self.config.rigid_abs_tol, self.config.rigid_rel_tol,
                                           offsets=offsets)

    def reset(self) -> None:
        """Forget every label (e.g. a new subject); keeps the body."""
        self._pos[:] = np.nan
        self._seen[:] = -np.inf
        self._skel = []
        self._fit = (-math.inf, math.nan)
        self._facing = None
        self._t_lost = self._t_ambiguous = None
        self._steady = self._best_prev = None
        self._reset_timers()
        self._free_hist = []
        self._on_point[:] = -np.inf
        self._legs_unsure = False

    def _reset_timers(self) -> None:
        """Forget what the swap rules saw held over time: it was about the names before."""
        self._knees_crossed_since = None
        self._cross_since = None
        self._cross_seen = -np.inf
        self._arm_swap_since = [None, None]
        self._fit_swap = None
        self._refit = None
        self._glue = ([], [])
        self._together = {}

    # ------------------------------------------------------------------ per frame
    def label(self, packets: list, t: float) -> tuple[np.ndarray, LabelQuality]:
        """Name the markers of one frame. packets: per camera (rig order) a MarkerPacket or None;
        t: seconds. Returns ((8, 3) world metres, NaN = not named; quality)."""
        self._renamed = 0
        self._lined_prev, self._lined = self._lined, set()
        out, q = self._label(packets, t)
        self._named_prev = (out.copy(), self._pts)
        self.still.update(self._views, self._blobs_of(out), t, identified=q.mode == "identified")
        q.renamed = self._renamed
        self.stats.renames += int(self._renamed != 0)
        self.last_quality = q
        self._named_last = bool(np.isfinite(out).all(axis=1).any())
        return out, q

    def loose(self, markers: np.ndarray, pts: Points3D | None = None) -> np.ndarray:
        """(8,) bool: the named markers of this frame's markers (8, 3) world m (NaN = not named;
        or of the frame whose points are pts) whose position is rough: on a point that fewer
        than two views saw in a blob of its own
        (in the others the blob was merged: the point may lie between two markers; 2 cm rms
        against 5 mm on the labelling benchmark), placed by reflection, twice the size of one
        marker everywhere, or named twice; or on no point at all (placed beside a merged point,
        or found from blobs another point also used). ``samba-process``'s final two-way solve
        weighs them less (``sigma_loose``; :mod:`samba_server.both_ways`)."""
        named = np.isfinite(markers).all(axis=1)
        out = named.copy()
        pts = self._pts if pts is None else pts
        p, on = self._points_of(markers, pts)
        if not on.any():
            return out
        rough = (pts.n_views - pts.n_merged < 2) | pts.mirrored | pts.merged_all  # (P,)
        twice = np.bincount(p[on], minlength=len(pts)) > 1  # (P,) points two names share
        out[on] = (rough | twice)[p[on]]
        return out

    def unseparated(self, markers: np.ndarray) -> np.ndarray:
        """(8,) bool: both wrists of this frame's markers (8, 3) world m (NaN = not named), when
        both are named and neither was seen apart from the other in ``apart_views`` views (a
        blob the other wrist's point does not use, of a single marker's size or with the other
        wrist on a blob of its own in that view); a wrist rescued from two views' blobs
        (:meth:`_rescue`) is seen in those two, one on no point (placed beside a merged point)
        nowhere. Hands together on a hilt or a bat leave the two wrists' names a coin flip that
        no view can settle: 14-16 cm swapped for a second in a swordplay. The server's poses and
        ``samba-process``'s two-way output carry them unnamed; the solves still use them (the
        two-way one loosely) and raise the wrists' and elbows' bounds to the distance between
        the wrists (:func:`~samba_server.recon.bounds.mirrored_wrists`). Not for wrists named
        more than ``together_m`` apart on points of their own that fit their blobs within the
        points stage's ``rough_px``, no view's blob shared: a subject standing still, hands
        hanging 52 cm apart, each wrist's blob merged with another marker's in the views that
        saw it and the other wrist hidden there, had both wrists unnamed in 32 of the take's
        last 40 frames (006_02 seed 649), names no track could have confused. Rough points
        stay flagged: a climber's wrists named 35 cm apart on two 2-view ghosts (1.3 px rough,
        17-23 cm off) were better a gap (001_14 seed 647: without that condition 96.3 -> 95.2 %
        of frames all right, confidently wrong 2.56 -> 3.92 % of its confident frames). All
        False with ``apart_views`` 0."""
        out = np.zeros(N_MARKERS, bool)
        need = self.config.apart_views
        if need <= 0 or not np.isfinite(markers[[LW, RW]]).all():
            return out
        p, on = self._points_of(markers)
        blobs = self._blobs_of(markers, (p, on))
        lw, rw = blobs[LW], blobs[RW]
        if np.linalg.norm(markers[LW] - markers[RW]) > self.config.together_m and not ((lw >= 0) & (lw == rw)).any() \
                and on[[LW, RW]].all() and (self._pts.error[p[[LW, RW]]] <= self.points.config.rough_px).all():
            return out
        if (lw >= 0).any() and np.array_equal(lw, rw):
            out[[LW, RW]] = True
            return out
        for m, other in ((LW, RW), (RW, LW)):
            theirs = blobs[other]
            apart = sum(1 for c, b in enumerate(blobs[m])
                        if b >= 0 and b != theirs[c] and (self._views[c].capacity[b] == 1 or theirs[c] >= 0))
            if apart >= need:
                return out
        out[[LW, RW]] = True
        return out

    def _blobs_of(self, markers: np.ndarray, points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(8, C) the blob per view of the point each marker of markers (8, 3) m is named on, or of
        the two blobs it was rescued from (:meth:`_rescue`); -1 where it has none (not named, not
        seen in that view, or on no point: placed beside a merged point). points: the markers'
        :meth:`_points_of`, when the caller has looked them up."""
        out = np.full((N_MARKERS, len(self._views)), -1, np.int64)
        p, on = self._points_of(markers) if points is None else points
        if on.any():
            out[on] = self._pts.blob[:, p[on]].T
        for X, blobs in self._rescue_blobs:
            out[np.linalg.norm(np.asarray(markers, float) - X, axis=1) <= 1e-6] = blobs
        return out

    def _points_of(self, markers: np.ndarray, pts: Points3D | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(8,) this frame's point (or pts') nearest each marker of markers (8, 3) m, and (8,)
        bool: the marker is named on that point."""
        pts = self._pts if pts is None else pts
        if pts is None or not len(pts):
            return np.zeros(N_MARKERS, np.int64), np.zeros(N_MARKERS, bool)
        d = np.linalg.norm(np.asarray(markers, float)[:, None, :] - pts.X[None], axis=2)  # (8, P)
        p = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)
        return p, np.isfinite(markers).all(axis=1) & (d[np.arange(N_MARKERS), p] <= 1e-6)

    @property
    def legs_unsure(self) -> bool:
        """Whether the last frame's leg names may be each other's, left for right. Legs named
        afresh (by an identification, or from the skeleton's prediction with no leg marker
        tracked) are unsure until the knees are named on points of their own (not on a merged
        point's midpoint) at least ``legs_sure_m`` apart along the subject's right, the left one on
        the left; tracked since, the names are then sure (their mirror image would have the
        thighs crossed, which the CMU clips do by 6 cm in 0.5 % of frames). Feet one behind the
        other under the hips (a lunge, a dancer's fourth position) fit both namings equally
        well: the markers say nothing of which leg is which, and a re-identification there
        names them by a coin flip that tracking then keeps (a dance after a blackout had both
        legs' joints 37-63 cm off for the whole last second, its bounds 2 cm). The server
        raises the knees' and ankles' bounds to the distance between the two sides while this
        holds (:func:`samba_server.recon.bounds.mirrored_legs`)."""
        return self._legs_unsure

    def _legs_fresh(self, out: np.ndarray, named: np.ndarray, t: float, reset: bool) -> bool:
        """Whether this frame names a leg marker that no leg track carries on: no leg marker was
        named within ``track_timeout`` (the names come from the skeleton's prediction), or the
        names were reset (an identification) other than where every named leg's track was."""
        on = _LEG_MARKERS[named[_LEG_MARKERS]]
        if not on.size:
            return False
        recent = t - self._seen[on] <= self.config.track_timeout
        if not recent.any():
            return True
        if not reset:
            return False
        near = np.linalg.norm(np.nan_to_num(out[on] - self._pos[on], nan=1.0), axis=1) <= self.config.gate_m
        return not (recent & near).all()

    def _legs_confirmed(self, out: np.ndarray, t: float) -> bool:
        """The knees of out (8, 3) named on two points at least ``legs_sure_m`` apart along the
        subject's right, the left one on the left. Not on a point (two markers placed either
        side of a merged point, along the subject's right: that proves nothing), nor on a point
        seen only in blobs twice a marker's size (it may lie between the two knees)."""
        if self._facing is None or t - self._t_facing > 0.5:
            return False
        p, on = self._points_of(out)
        if not on[[LK, RK]].all() or p[LK] == p[RK] or self._pts.merged_all[p[[LK, RK]]].any():
            return False
        return float((out[RK] - out[LK]) @ right_of(self._facing)) >= self.config.legs_sure_m

    def _label(self, packets: list, t: float) -> tuple[np.ndarray, LabelQuality]:
        self.stats.frames += 1
        self._t_prev, self._t_frame = self._t_frame, t
        self._rescued[:] = False
        self._rescue_blobs = []
        self._views = [view_blobs(p) for p in packets]
        clutter = self._clutter = self.still.clutter(self._views, t)
        pts = every = self._pts = self.points.reconstruct(self._views, clutter)
        if len(pts) >= 2:
            self.stats.frames_with_points += 1
            sure = pts.X[pts.n_views >= 3]
            if len(sure) >= 3:
                # the body's travel: the median of the points no ghost makes (the mean of all
                # points jumped as 2-view ghosts came and went: "walking backwards" after a blackout)
                self._centres = [c for c in self._centres if t - c[0] <= 0.5] + [(t, median_rows(sure))]
        pred, gate = self._predict(t)
        n_pred = int(np.isfinite(pred).all(axis=1).sum())
        q = LabelQuality(n_points=len(pts))
        out = np.full((N_MARKERS, 3), np.nan)
        real = self._real(every, clutter)
        if n_pred >= self.config.min_tracked:
            pts = self._pts = real
        if n_pred >= self.config.min_tracked and len(pts):
            self._uncross(pts, pred)
            out, q, assign = self._track(pts, pred, gate, t)
            self._unglue(out, assign, t)
            q.n_labelled += self._rescue(pts, out, assign, pred, t)
            explained = q.n_labelled >= min(len(pts), N_MARKERS) - 2 or q.n_labelled >= 6
            if explained:
                self._t_good = t
            if t - self._t_good <= self.config.lost_after:
                audited = self._audit(pts, out, assign, q, t)
                if audited is not None:
                    out, q, kept = audited
                    # an audit that only adds names keeps the tracks; one that renames restarts
                    # them (an unclear one, all but the names it kept)
                    self._update(out, t, reset=q.mode == "identified", shared=self._shared, kept=kept)
                    return out, q
                self._update(out, t, shared=self._shared)
                return out, q
            log.debug("t=%.3f: tracking explains %d of %d points: identifying again", t, q.n_labelled, len(pts))
        # (a subject standing still, never named, makes clutter of every blob: then all of them)
        pts = self._pts = real if len(real) >= _IDENTIFY_REAL else every
        if self._t_lost is None and len(pts) >= 2:
            self._t_lost = t
        found = self._identify(pts, t)
        if found is not None:
            out, q = found
            self._renamed = _ALL if self._named_last else 0  # names tracking still held, replaced
            self._update(out, t, reset=True)
            self._t_good = t
        else:
            q = LabelQuality(n_points=len(pts), mode="lost")
        return out, q

    @staticmethod
    def _real(pts: Points3D, clutter: list[np.ndarray]) -> Points3D:
        """pts without the points fewer than two views see in blobs that are not clutter (per
        view (N,) bool): one marker's blob crossed with a static reflection's. Case: a subject
        standing still at the volume's edge, a wrist and an ankle each seen by one camera, each
        crossed with a reflection in a camera that saw neither: tracking named both there, 38
        and 21 cm off, for 0.8 s, and the backward pass's first identification did too (006_02
        seed 651)."""
        stale = on_clutter(pts.blob, clutter)
        lone = (stale > 0) & ((pts.blob >= 0).sum(axis=0) - stale < 2)
        return pts.subset(~lone) if lone.any() else pts

    def _predict(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        pred = np.full((N_MARKERS, 3), np.nan)
        gate = np.zeros(N_MARKERS)
        age = t - self._seen
        recent = age <= cfg.track_timeout
        pred[recent] = self._pos[recent] + self._vel[recent] * age[recent, None]
        gate[recent] = np.minimum(cfg.gate_m + cfg.gate_growth * age[recent], cfg.max_gate_m)
        skel = self._skeleton(t)
        if skel is not None:
            use = ~recent & np.isfinite(skel).all(axis=1)
            pred[use] = skel[use]
            gate[use] = cfg.skeleton_gate_m
        return pred, gate

    def _skeleton(self, t: float) -> np.ndarray | None:
        if not self._skel or t - self._skel[-1][0] > self.config.skeleton_max_age:
            return None
        t1, m1 = self._skel[-1]
        if len(self._skel) == 1:
            return m1
        t0, m0 = self._skel[0]
        if t1 <= t0:
            return m1
        return m1 + (m1 - m0) * min(t - t1, 0.1) / (t1 - t0)

    def _track(self, pts: Points3D, pred: np.ndarray, gate: np.ndarray,
               t: float) -> tuple[np.ndarray, LabelQuality, np.ndarray]:
        """Name the points after the predictions pred (8, 3) within gate (8,) m: (8, 3) markers,
        quality, and (8,) the point per marker (-1 = unnamed)."""
        cfg = self.config
        P = len(pts)
        # a point seen only in merged blobs may stand for two markers: it gets a second row
        row_pt = np.r_[np.arange(P), np.flatnonzero(pts.merged_all)]
        Pr = len(row_pt)
        X = pts.X[row_pt]
        d = np.linalg.norm(X[:, None, :] - pred[None, :, :], axis=2)  # (Pr, 8)
        half = np.where(pts.merged_all[row_pt], cfg.merged_half_m, 0.0)[:, None]
        d_eff = np.maximum(d - half, 0.0)
        ghostly = np.where(pts.n_views[row_pt] < 3, np.minimum(pts.unexplained[row_pt], 2), 0)
        cost = d_eff - cfg.hint_m * pts.votes[row_pt] + cfg.merged_m * pts.merged[row_pt, None] \
            + cfg.unexplained_m * ghostly[:, None]
        stale = self._seen < self._t_prev - 1e-6  # (8,) not named last frame
        if stale[[LW, RW]].any() and np.isfinite(pred[[LS, RS]]).all():
            # a wrist not named last frame (its prediction stale) costs for being nearer the other
            # shoulder than its own: arms cross little, and two hands on one sword hilt part
            # with one stale prediction between them
            dl, dr = (np.linalg.norm(X - pred[s], axis=1) for s in (LS, RS))
            for w, extra in ((LW, dl - dr), (RW, dr - dl)):
                if stale[w]:
                    cost[:, w] += cfg.wrist_side_w * np.maximum(0.0, extra)
        ok = np.isfinite(d) & (d_eff <= gate[None, :])
        # a rough 2-view point two views miss (merged blobs' centroids paired up) is no place
        # to find a marker predicted from the skeleton (unseen longer than track_timeout)
        rough = (pts.n_views[row_pt] < 3) & (pts.unexplained[row_pt] >= 2) & (pts.error[row_pt] > self.points.config.rough_px)
        ok &= ~(rough[:, None] & (t - self._seen > cfg.track_timeout)[None, :])
        # nor for a tracked marker far from where it was going (a knee whose point vanished
        # behind the other leg jumped 15 cm onto such a ghost)
        ok &= ~(rough[:, None] & (d > cfg.rough_jump_m))
        big = 1e3
        full = np.full((Pr, N_MARKERS + Pr), big)
        full[:, :N_MARKERS] = np.where(ok, cost, big)
        full[np.arange(Pr), N_MARKERS + np.arange(Pr)] = cfg.max_gate_m
        rows, cols = linear_sum_assignment(full)
        arow = np.full(N_MARKERS, -1, np.int64)
        for r, c in zip(rows, cols):
            if c < N_MARKERS and ok[r, c]:
                arow[c] = r
        assign = np.where(arow >= 0, row_pt[np.maximum(arow, 0)], -1)
        # a marker left out whose prediction sits by a named neighbour's point, close to that
        # neighbour's prediction, is in the same blob in every view: it shares the point
        free = np.flatnonzero(np.bincount(assign[assign >= 0], minlength=P) == 0)
        for n in np.flatnonzero((assign < 0) & np.isfinite(pred).all(axis=1)):
            if free.size and np.min(np.linalg.norm(pts.X[free] - pred[n], axis=1)) <= gate[n] + 0.1:
                continue  # a point of its own may be there: no sharing
            best = None
            for m in np.flatnonzero(assign >= 0):
                legs = (min(m, n), max(m, n)) in _LEG_PAIRS
                if np.count_nonzero(assign == assign[m]) > 1 or not _two_in_one(pts, assign[m], legs):
                    continue
                sep = float(np.linalg.norm(pred[m] - pred[n]))
                dn = float(np.linalg.norm(pts.X[assign[m]] - pred[n]))
                if sep <= 2 * cfg.merged_half_m + 0.04 and dn <= gate[n] + cfg.merged_half_m and \
                        (best is None or dn < best[0]):
                    best = (dn, m)
            if best is not None:
                assign[n], arow[n] = assign[best[1]], arow[best[1]]
        out = np.full((N_MARKERS, 3), np.nan)
        out[assign >= 0] = pts.X[assign[assign >= 0]]
        self._part(out, assign, arow, t)
        right = None
        if self._facing is not None and t - self._t_facing <= 0.5:
            right = right_of(self._facing)
        if right is not None:
            # legs do not cross: a right knee (ankle) well to the left of the left one is a swap,
            # unless swapping it makes the shins fit worse (feet staggered in a stance turned
            # against the shoulders put the right ankle left of the left one, the knees not).
            # Legs tracked frame to frame may cross (a crossover step): they are swapped only
            # when that makes the shins fit clearly better; with one shin to go by (a knee
            # unnamed, the other perhaps on a merged point between the knees) by as much as
            # the feet must fit better to be named crossed (cross_gain_m; with three cameras
            # or more, as that rule: with two, the 2-camera benchmark's unseen set lost 1.7 points)
            crossed = [(lm, rm) for lm, rm in _LEG_PAIRS
                       if assign[lm] >= 0 and assign[rm] >= 0 and assign[lm] != assign[rm]
                       and float((out[rm] - out[lm]) @ right) < -cfg.crossed_m]
            # both pairs crossed is a whole-leg swap, which keeps both shins: they cannot tell
            # it from a stance turned against the shoulders (a dancer twisting against her
            # hips; a fencer), which is named so. The knees' hold decides (_uncross_knees).
            # With three cameras or more (measured there; with two the rule stays as it was)
            # (a marker on a point that may lie between two markers has no shin to go by:
            # _between; a kneeling child's hidden knees on such points uncrossed her ankles,
            # crossed and named right, for the last 1.6 s of the take: seed 3 005_12 at x0.75)
            if len(crossed) == 1 or (crossed and len(self.rig) < 3):
                firm = np.where(_between(pts, assign)[:, None], np.nan, out)
                swapped = firm.copy()
                for lm, rm in crossed:
                    swapped[[lm, rm]] = firm[[rm, lm]]
                slack = 0.02 if any(stale[m] for pair in crossed for m in pair) else -0.005
                if slack < 0 and len(self.rig) >= 3 and not np.isfinite(firm[[LK, RK, LA, RA]]).all():
                    slack = -cfg.cross_gain_m
                if self._body.shin_misfit(swapped) <= self._body.shin_misfit(firm) + slack:
                    log.debug("t=%.3f s: %s uncrossed", t, crossed)
                    for lm, rm in crossed:
                        self._renamed |= (1 << lm) | (1 << rm)
                        assign[[lm, rm]], arow[[lm, rm]], out[[lm, rm]] = assign[[rm, lm]], arow[[rm, lm]], out[[rm, lm]]
            self._uncross_knees(out, assign, arow, right, t)
        continued = self._sharing_t == self._t_prev
        self._sharing = {(m, n): self._sharing.get((m, n), t) if continued else t for m, n in _KNEE_OTHER_ANKLE
                         if assign[m] >= 0 and assign[m] == assign[n]}
        self._sharing_t = t
        self._split_shared(out, assign, pts, pred, right)
        self._shared = np.array([np.count_nonzero(assign == a) > 1 if a >= 0 else False for a in assign])
        for m, n in _KNEE_OTHER_ANKLE:
            if assign[m] >= 0 and assign[m] == assign[n]:
                self._together[(m, n)] = t
        self._swap_for_shins(out, assign, arow, right)
        self._cross_for_shins(out, assign, arow, right, t)
        self._swap_arms(out, assign, arow, t)
        self._wrists_by_reach(out, assign, arow)
        # rigid distances and facing: drop the worse-predicted marker of a violating group
        for group in self._body.violations(out, narrowing=True):
            worst = max(group, key=lambda m: d[arow[m], m])
            out[worst] = np.nan
            assign[worst] = arow[worst] = -1
        if assign[LS] >= 0 and assign[RS] >= 0 and self._facing is not None:
            # the body turns at most ~2 turns/s: a facing far from the last one is a mislabel
            f = facing_of(out[LS], out[RS])
            limit = math.cos(min(math.pi, math.radians(cfg.turn_slack_deg) + cfg.max_turn_rate * (t - self._t_facing)))
            if f is not None and float(f @ self._facing) < limit:
                out[[LS, RS]] = np.nan
                assign[[LS, RS]] = arow[[LS, RS]] = -1
        # markers left out, or dropped above, found again from the free points
        lost_before = assign < 0
        self._recover(pts, pred, assign, arow, row_pt)
        back = lost_before & (assign >= 0)
        out[back] = pts.X[assign[back]]
        self._swap_to_fit(out, pred, assign, arow, t)
        named = np.flatnonzero(assign >= 0)
        margin = float("nan")
        if named.size:
            rival = np.where(ok[:, named] & (row_pt[:, None] != assign[named]), cost[:, named], np.inf)
            runner = np.minimum(rival.min(axis=0), gate[named])
            margin = float(np.min(runner - cost[arow[named], named]))
        over = int(sum(1 for m in named if pts.votes[assign[m]].sum() > pts.votes[assign[m], m]))
        self.stats.overridden += over
        resid = float(np.sqrt(np.mean(d_eff[arow[named], named] ** 2))) if named.size else float("nan")
        return out, LabelQuality(int(named.size), P, margin, resid, "tracking", over), assign

    def _part(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray, t: float) -> None:
        """A knee and the other leg's ankle that shared a merged point within ``part_s`` and are
        now named on two points take each other's point when that fits both shins by
        ``part_gain_m`` better. Where they parted, both predictions stood at the merged point and
        say little: a dancer's raised right ankle leaving the left knee took the knee's point
        (the knee the ankle's, then dropped for its broken shin) for the rest of the step
        (005_11, both held-out seeds). Only this pair: both its markers are held by a shin on
        each side, while a wrist parting from a shoulder or a knee is not (tried for every pair
        of markers not a left-right one: wrists and shoulders swapped wrongly as often as
        rightly). With three cameras or more: with two, whose points are often ghosts, it lost
        a climbing take (the 2-camera benchmark from 8 s: 001_08 41.5 -> 31.4 %) and gained
        none. out (8, 3), assign, arow (8,) in place."""
        cfg = self.config
        self._together = {k: ts for k, ts in self._together.items() if t - ts <= cfg.part_s}
        if len(self.rig) < 3:
            return
        for m, n in list(self._together):
            if assign[m] < 0 or assign[n] < 0 or assign[m] == assign[n]:
                continue
            swapped = out.copy()
            swapped[[m, n]] = out[[n, m]]
            gain = self._body.shin_misfit(out) - self._body.shin_misfit(swapped)
            if gain >= cfg.part_gain_m:
                log.debug("t=%.3f s: %d and %d parted swapped: the shins fit %.3f m better", t, m, n, gain)
                for a in (out, assign, arow):
                    a[[m, n]] = a[[n, m]]
                self._renamed |= (1 << m) | (1 << n)
                del self._together[(m, n)]

    def _rescue(self, pts: Points3D, out: np.ndarray, assign: np.ndarray, pred: np.ndarray, t: float) -> int:
        """Markers tracked until the last frame (seen within ``track_timeout``) that no point
        stands for, where two views each hold a blob near the marker's projection (a hand in front
        of the chest hidden from two cameras: the other two see it, but a point of the knee behind
        it, seen in three views, took its blob in one of them). The two blobs, at least one used
        by no point, or both used only by unnamed points that are 2-view (two shoulders seen by
        the same two cameras on one epipolar plane of theirs: the points stage paired each one's
        blob with the other's, two ghosts 40-50 cm off, and both shoulders went unnamed) or rough
        (error over the points stage's ``rough_px``: a fencer's right shoulder's two blobs went
        into a 3-view ghost 27 cm off, 0.58 px, with the left shoulder's blob in a third view;
        002_08 seed 638), are triangulated; the point is taken when it meets both rays within
        ``rescue_px`` (a marker's own two blobs meet within 0.25 px; a blob pair that only
        happens to lie near the prediction mostly does not), lies within ``rescue_m`` of the
        prediction (plus ``rescue_growth`` times the time since the marker was last named: a
        dribbler's wrist coming out from behind the body, its track last named on rough points,
        was predicted 7.3 cm off after 0.12 s, 002_09 seed 629) and ``rescue_m`` nearer it than
        any other marker's, is no other point and lies
        in the capture volume; for at most ``rescue_max_s`` after the marker was last named on a
        point (rescues alone do not keep a track alive: one gone astray would live on ghosts).
        out (8, 3), assign (8,) (the point per marker, -1 none) from tracking; pred (8, 3). Fills
        out in place; returns how many markers it named. Three cameras or more: with two, a
        marker the points stage left without a point is mostly a ghost pair it rejected
        (swordplay lost 8 points). Knees and ankles only while the legs' names are sure
        (:attr:`legs_unsure` False), shoulders and wrists always (:data:`_UPPER`): a knee or
        ankle that goes unnamed for a frame is how the legs' swap rules get to see a swapped
        pair (a dance's legs, named the other way round after a blackout, kept those names 0.8 s
        longer when the left knee was rescued on the right knee's blobs), and names given afresh
        are unsure until the knees are seen apart. Sure, a leg is rescued like an arm: a dancer's
        ankles at the volume's edge, side by side on an epipolar plane of the only two cameras
        that see them, lost both their points to a chain of ghosts (one ankle's blob with the
        other's, the other's with a static distractor's merged blob) and went unnamed for 0.9 s
        (006_02 seed 629)."""
        cfg = self.config
        C = len(self._views)
        if cfg.rescue_m <= 0 or C < 3:
            return 0
        age = t - self._seen
        which = _UPPER if self._legs_unsure else tuple(range(N_MARKERS))
        todo = [m for m in which if assign[m] < 0 and not np.isfinite(out[m]).all()
                and age[m] <= cfg.track_timeout and np.isfinite(pred[m]).all()
                and t - self._on_point[m] <= cfg.rescue_max_s]
        if not todo:
            return 0
        tri = self.points.tri
        proj, depth = tri.project(pred[todo])  # (C, M, 2) px, (C, M) m
        taken = [set(pts.blob[c][pts.blob[c] >= 0].tolist()) for c in range(C)]
        # blobs held by a point other than an unnamed 2-view or rough one (which may be the
        # crossed pairing of two markers' blobs in the same two views: a ghost of each)
        ghostly = (pts.n_views == 2) | (pts.error > self.points.config.rough_px)
        ghostly[assign[assign >= 0]] = False
        held = [set(pts.blob[c][(pts.blob[c] >= 0) & ~ghostly].tolist()) for c in range(C)]
        found = 0
        for i, m in enumerate(todo):
            reach = cfg.rescue_m + cfg.rescue_growth * max(float(age[m]), 0.0)  # m
            near: list[list[int]] = []
            for c, v in enumerate(self._views):
                if len(v) == 0 or not depth[c, i] > 0.1:
                    near.append([])
                    continue
                r = reach * self.points.f[c] / depth[c, i] + 1.0
                dist = np.linalg.norm(v.uv - proj[c, i], axis=1)
                near.append(np.flatnonzero((dist <= r) & ~self._clutter[c]).tolist())  # (no reflection: _real)
            combos = [(a, b, ba, bb) for a, b in itertools.combinations(range(C), 2)
                      for ba in near[a] for bb in near[b]
                      if ba not in taken[a] or bb not in taken[b] or (ba not in held[a] and bb not in held[b])]
            if not combos:
                continue
            uv = np.full((C, len(combos), 2), np.nan)
            for k, (a, b, ba, bb) in enumerate(combos):
                uv[a, k], uv[b, k] = self._views[a].uv[ba], self._views[b].uv[bb]
            res = tri.triangulate(uv)
            dp = np.linalg.norm(res.points - pred[m], axis=1)
            others = np.r_[pts.X, out[np.isfinite(out).all(axis=1)]]
            # and nearer this marker's prediction than any other's (hands together: the other
            # wrist's blobs, its point missing too, are not this one's)
            rival = np.delete(pred, m, axis=0)
            rival = rival[np.isfinite(rival).all(axis=1)]
            good = np.flatnonzero(np.isfinite(dp) & (dp <= reach) & (res.error <= cfg.rescue_px)
                                  & (_nearest(res.points, others) >= cfg.points.min_separation_m)
                                  & (_nearest(res.points, rival) >= dp + cfg.rescue_m)
                                  & self.points.plausible(res.points))
            if good.size:
                k = good[np.argmin(dp[good])]
                out[m] = res.points[k]
                self._rescued[m] = True
                a, b, ba, bb = combos[k]
                blobs = np.full(C, -1, np.int64)
                blobs[a], blobs[b] = ba, bb
                self._rescue_blobs.append((out[m].copy(), blobs))
                found += 1
        return found

    def _uncross(self, pts: Points3D, pred: np.ndarray) -> int:
        """Two 2-view points of the same two views, neither within ``rescue_m`` of any marker's
        prediction (pred (8, 3) m), whose blobs paired the other way round meet within
        ``rescue_px`` each and lie within ``rescue_m`` of two different markers' predictions,
        are those two markers: the points stage paired each one's blob in one view with the
        other's in the second. Two ankles side by side on one epipolar plane of the only two
        cameras that see them (the body hiding them from the other two) make both pairings fit;
        the true pair projects into the hiding views with no blob there, the crossed ghosts,
        30 cm off, where no camera looks, so the ghosts ranked first, and both ankles of a dance
        went unnamed for 26 frames (006_02, seed 602). Replaces the two points in pts in place
        (X, error, blob, unexplained, votes, behind); returns how many pairs it re-paired. Off with
        ``rescue_m`` 0."""
        cfg = self.config
        have = np.isfinite(pred).all(axis=1)
        two = np.flatnonzero(pts.n_views == 2)
        if cfg.rescue_m <= 0 or have.sum() < 2 or len(two) < 2:
            return 0
        markers = np.flatnonzero(have)

        def near(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """(N,) distance (m) from each point of X (N, 3) to the nearest prediction, (N,) its marker."""
            d = np.linalg.norm(X[:, None] - pred[markers][None], axis=2)
            return d.min(axis=1), markers[d.argmin(axis=1)]

        far = two[(near(pts.X[two])[0] > cfg.rescue_m) & ~pts.mirrored[two]]
        far = far[(pts.blob[:, far] >= 0).sum(axis=0) == 2]  # (a parted point may list more views)
        if len(far) < 2:
            return 0
        # per far point, view and marker: its blob there (a single marker's) lies by the marker's
        # predicted projection. A pairing the other way round can only land on a marker whose
        # projections both blobs lie by: clutter's ghosts mostly have none, so few pairs are tried.
        C = len(self._views)
        proj, depth = self.points.tri.project(pred[markers])  # (C, M, 2) px, (C, M) m
        radius = cfg.rescue_m * self.points.f[:, None] / np.maximum(depth, 0.1) + 1.0  # (C, M) px
        by = np.zeros((len(far), C, len(markers)), bool)
        for c, v in enumerate(self._views):
            b = pts.blob[c, far]
            has = np.flatnonzero(b >= 0)
            if has.size:
                d = np.linalg.norm(v.uv[b[has]][:, None] - proj[c][None], axis=2)  # (H, M) px
                by[has, c] = (d <= radius[c]) & (depth[c] > 0.1) & (v.capacity[b[has]] == 1)[:, None]
        cams = np.nonzero((pts.blob[:, far] >= 0).T)[1].reshape(-1, 2)  # (F, 2) each point's two views
        rows = np.arange(len(far))
        useful = np.flatnonzero(by[rows, cams[:, 0]].any(axis=1) & by[rows, cams[:, 1]].any(axis=1)).tolist()
        done: set[int] = set()
        for j, i in enumerate(useful):
            for k in useful[j + 1:]:
                p, q = int(far[i]), int(far[k])
                if p in done or q in done or (cams[i] != cams[k]).any():
                    continue
                a, b = cams[i].tolist()
                if not ((by[i, a] & by[k, b]).any() and (by[k, a] & by[i, b]).any()):
                    continue
                blobs = pts.blob[[a, b]][:, [p, q]]  # (2 views, 2 points)
                if (blobs[:, 0] == blobs[:, 1]).any():
                    continue
                swapped = blobs[:, ::-1].copy()
                swapped[0] = blobs[0]  # view a keeps its blobs, view b's are exchanged
                uv = np.full((C, 2, 2), np.nan)
                uv[a] = self._views[a].uv[swapped[0]]
                uv[b] = self._views[b].uv[swapped[1]]
                res = self.points.tri.triangulate(uv)
                d, m = near(res.points)
                others = np.delete(pts.X, [p, q], axis=0)
                if not ((res.error <= cfg.rescue_px).all() and (d <= cfg.rescue_m).all() and m[0] != m[1]
                        and (_nearest(res.points, others) >= cfg.points.min_separation_m).all()
                        and self.points.plausible(res.points).all()):
                    continue
                log.debug("points %d and %d re-paired in views %d and %d: markers %s", p, q, a, b, m.tolist())
                pts.X[[p, q]], pts.error[[p, q]] = res.points, res.error
                pts.blob[b, [p, q]] = swapped[1]
                pts.votes[[p, q]] = blob_votes(self._views, pts.blob[:, [p, q]])
                pts.unexplained[[p, q]] = self.points.missed(pts.X[[p, q]], self._views, pts.blob[:, [p, q]])
                if pts.behind is not None:
                    pts.behind[[p, q]] = 0
                done |= {p, q}
        return len(done) // 2

    def _recover(self, pts: Points3D, pred: np.ndarray, assign: np.ndarray, arow: np.ndarray,
                 row_pt: np.ndarray) -> None:
        """Name markers left out by the gated assignment to points nobody took, when the choice
        is clear: a marker whose prediction has drifted (its track lost, the skeleton wrong
        about it) would otherwise never be found again.

        A point that is surely a marker (>= 3 views, or no view missing it) is a candidate for a
        marker within ``recover_gate_m`` of its prediction (a shoulder or wrist within
        ``gate_m`` + ``recover_speed`` times the time since it was last named: how far it can
        have gone; a climber's shoulder and hand level with the cameras, whose blobs pair up
        across the views either way, were named on the other pairing's two points, 30-35 cm
        off their predictions, a frame after both were last named); it, or a 2-view point that one
        other view misses, is a candidate where the named markers put it: a shoulder a shoulder
        width from the other along the subject's right, a knee a shin above its ankle, an ankle
        a shin below its knee. The candidates are assigned optimally; a pair is kept when the
        best assignment without it costs ``recover_margin_m`` more and the marker's rigid
        distances hold. A leg with neither marker named is first looked for as a
        pair (:meth:`_recover_leg`), both ankles (or both knees) by the shins alone
        (:meth:`_recover_ends`). assign, arow (8,) in place."""
        cfg = self.config
        body = self._body
        self._recover_leg(pts, pred, assign, arow, row_pt)
        self._recover_ends(pts, assign, arow, row_pt)
        named = _named_on(pts, assign)
        lost = np.flatnonzero(assign < 0)
        free = _recoverable(pts, assign)
        if not lost.size or not free.size:
            return
        X = pts.X[free]
        # a 2-view point that a third view should have seen may be a ghost: placed by the
        # rigid lengths only, at a higher cost
        doubt = np.where((pts.n_views[free] < 3) & (pts.unexplained[free] > 0), cfg.unexplained_m, 0.0)
        cost = np.full((len(free), len(lost)), np.inf)
        right = None if self._facing is None else right_of(self._facing)
        wrist_anchor = self._wrist_anchors(pts, X, free, doubt, assign, named, lost)
        for j, m in enumerate(lost):
            if np.isfinite(pred[m]).all():
                d = np.linalg.norm(X - pred[m], axis=1)
                reach = cfg.recover_gate_m
                if m in _UPPER:  # (knees in a kick outrun their predictions: 005_05 lost 2.4 points)
                    reach = min(reach, cfg.gate_m + cfg.recover_speed * (self._t_frame - self._seen[m]))
                cost[:, j] = np.where((d <= reach) & (doubt == 0), d, np.inf)
            anchor = np.full(len(free), np.inf)
            if m in (LS, RS) and right is not None:
                other, sign = (RS, -1.0) if m == LS else (LS, 1.0)
                if assign[other] >= 0:
                    d = np.linalg.norm(X - (named[other] + sign * body.shoulder_width * right), axis=1)
                    anchor = np.where(d <= 3 * body.tol, d, np.inf)
            if m in wrist_anchor:
                anchor = wrist_anchor[m]
            for knee, ankle in ((LK, LA), (RK, RA)):
                if m == ankle and assign[knee] >= 0:
                    e = np.abs(np.linalg.norm(X - named[knee], axis=1) - body.shin)
                    anchor = np.where((e <= body.tol) & (X[:, 2] < named[knee][2]), e, np.inf)
                elif m == knee and assign[ankle] >= 0:
                    e = np.abs(np.linalg.norm(X - named[ankle], axis=1) - body.shin)
                    anchor = np.where((e <= body.tol) & (X[:, 2] > named[ankle][2]), e, np.inf)
            cost[:, j] = np.minimum(cost[:, j], cfg.anchor_m + anchor + doubt)
            for r in np.flatnonzero(np.isfinite(cost[:, j])):
                # a candidate that breaks a rigid distance to the named markers is none (left
                # in, it won the assignment and, rejected after it, kept a better pair out)
                trial = named.copy()
                trial[m] = X[r]
                if any(m in g for g in body.violations(trial)):
                    cost[r, j] = np.inf
        if not np.isfinite(cost).any():
            return
        # (points + markers) x (markers + points): a point may stay free at no cost, a marker
        # stay unnamed at cost 1 (more than any candidate)
        nf, nl = len(free), len(lost)
        full = np.full((nf + nl, nl + nf), 1e3)
        full[:nf, :nl] = np.where(np.isfinite(cost), cost, 1e3)
        full[np.arange(nf), nl + np.arange(nf)] = 0.0
        full[nf + np.arange(nl), np.arange(nl)] = 1.0
        full[nf:, nl:] = 0.0

        def total(c: np.ndarray) -> float:
            r, k = linear_sum_assignment(c)
            return float(c[r, k].sum())

        rows, cols = linear_sum_assignment(full)
        best = float(full[rows, cols].sum())
        for r, c in sorted(zip(rows, cols), key=lambda rc: full[rc]):
            if r >= nf or c >= nl or not np.isfinite(cost[r, c]):
                continue
            m, p = lost[c], free[r]
            alt = full.copy()
            alt[r, c] = 1e3  # the best labelling without this pair must be clearly worse
            if total(alt) - best < cfg.recover_margin_m:
                continue
            trial = named.copy()
            trial[m] = pts.X[p]
            if any(m in g for g in body.violations(trial)):
                continue
            named[m] = pts.X[p]
            _name_points(assign, arow, row_pt, (m,), (p,))

    def _wrist_anchors(self, pts: Points3D, X: np.ndarray, free: np.ndarray, doubt: np.ndarray,
                       assign: np.ndarray, named: np.ndarray, lost: np.ndarray) -> dict[int, np.ndarray]:
        """For :meth:`_recover`: per lost wrist, the cost (m; inf = no candidate) of naming it on
        each free point X (F, 3) (indices free (F,) into pts, ``doubt`` (F,) their ghost cost)
        by its arm alone, when the wrists are the only markers unnamed (assign (8,), named (8, 3)
        m with NaN rows unnamed, lost the unnamed markers); else none.

        A lost wrist is anywhere within its arm's reach, if nearer its own shoulder than the
        other one (else at ``wrist_side_w`` per metre), clear of the named markers (a point
        hugging one is more likely its ghost), not a static reflection, not a doubtful 2-view
        point whose every blob a named marker uses too (a ghost where two merged blobs' rays
        cross), and not a point whose every blob a named shoulder uses, doubtful or not (the
        rays of a right shoulder's merged blobs crossed 15.6 cm from it where no view missed
        them, and a dribbler's lost left wrist was named there 35 cm off, 002_09 seed 629; any
        named marker's: hands together on a hilt make such points of each other's blobs, and
        swordplay lost 1.7 points): a wrist lost where its prediction went wrong (hands
        together on a sword hilt) is found again.

        Both wrists lost, the rest named: the assignment and its margin settle which is which
        (a standing subject's hands, both hidden for 0.1 s after a blackout, were found by no
        prediction and left unnamed to the take's end, 002_03 seed 655), but only with two
        candidate points: one point may be both hands together, and the wrist whose shoulder
        is nearer is no better than a coin (a dribbler's hands on the ball, 002_08 seeds 3 and
        653), and each no farther from where it was last named than ``gate_m`` +
        ``recover_speed`` times the time since (two ghosts 40 cm behind a standard pose's hands,
        a reflection's rays crossing their blobs the frame they were hidden, took both)."""
        cfg, body = self.config, self._body
        wrists = [m for m in lost.tolist() if m in (LW, RW)]
        if len(wrists) != len(lost) or not len(X):
            return {}
        # what does not depend on which wrist: moving, no ghost of named markers' blobs
        allowed = (self._moving(X, self._t_frame)
                   & ((doubt == 0) | ~_borrowed(pts, free, assign[assign >= 0]))
                   & ~_borrowed(pts, free, assign[[LS, RS]][assign[[LS, RS]] >= 0]))
        out = {}
        for m in wrists:
            own, other = (LS, RS) if m == LW else (RS, LS)
            ds = np.linalg.norm(X - named[own], axis=1)
            do = np.linalg.norm(X - named[other], axis=1)
            others = np.delete(named, m, axis=0)
            clear = _nearest(X, others[np.isfinite(others).all(axis=1)])
            out[m] = np.where(allowed & (ds <= body.reach + body.tol) & (clear >= cfg.wrist_clear_m),
                              cfg.wrist_side_w * np.maximum(0.0, ds - do), np.inf)
        if len(out) == 2:
            if np.count_nonzero(np.isfinite(out[LW]) | np.isfinite(out[RW])) < 2:
                return {}
            for m in out:  # and no farther than it can have gone since it was last named
                if np.isfinite(self._pos[m]).all():
                    went = cfg.gate_m + cfg.recover_speed * (self._t_frame - self._seen[m])
                    out[m] = np.where(np.linalg.norm(X - self._pos[m], axis=1) <= went, out[m], np.inf)
        return out

    def _recover_leg(self, pts: Points3D, pred: np.ndarray, assign: np.ndarray, arow: np.ndarray,
                     row_pt: np.ndarray) -> None:
        """A leg with neither knee nor ankle named while the other leg has a name is found again
        as the only pair of free points that fits it: a shin apart, the knee above the ankle
        (a level shin's ends by :meth:`_one_fit`), within the rigid distances of the named
        markers (the same side's shoulder) and not crossed over the other leg (by
        ``crossed_m`` along the subject's right). The solver, with no marker on that leg,
        predicts it wherever its pose prior puts it (a subject bending to scoop something up
        had a leg predicted lifted, 0.5 m off, for a second), so its prediction is not asked
        (but for a level shin's ends, from tracks); either point may be one a view misses (legs
        hide each other). With two cameras every point is a 2-view point and ghosts pair up as
        easily as legs (the 2-camera benchmark lost 15 points on a jump take): the rule needs
        three. pred: (8, 3) m the markers' predictions; assign, arow (8,) in place; nothing
        before the facing is known."""
        if self._facing is None or len(self.rig) < 3:
            return
        body = self._body
        right = right_of(self._facing)
        if (assign[[LK, LA, RK, RA]] < 0).all() and (assign[[LS, RS]] >= 0).any():
            self._recover_legs(pts, pred, assign, arow, row_pt, right)
            return
        for (_s, _w, k, a), (_os, _ow, ok, oa) in ((SIDES[0], SIDES[1]), (SIDES[1], SIDES[0])):
            if assign[k] >= 0 or assign[a] >= 0 or (assign[ok] < 0 and assign[oa] < 0):
                continue
            named, pairs = self._free_shins(pts, assign)
            outward = right if k == RK else -right
            fits = []
            for i, j in pairs:
                knee, ankle = pts.X[i], pts.X[j]
                if any(assign[o] >= 0 and float((p - named[o]) @ outward) < -self.config.crossed_m
                       for o, p in ((ok, knee), (oa, ankle))):
                    continue
                trial = named.copy()
                trial[k], trial[a] = knee, ankle
                if not body.violations(trial):
                    fits.append((i, j))
            fit = self._one_fit(pts, pred, fits, (k, a))
            if fit is not None:
                log.debug("t=%.3f s: leg %d-%d found again as the one pair of points that fits it", self._t_frame, k, a)
                _name_points(assign, arow, row_pt, (k, a), fit)

    def _recover_ends(self, pts: Points3D, assign: np.ndarray, arow: np.ndarray, row_pt: np.ndarray) -> None:
        """Both ankles unnamed, both knees named (or the other way round): the feet close
        together fit both shins either way round, so the recovery's margin, made for the
        distance from a prediction, names neither (a walk whose ankles' tracks swapped as the
        feet passed left them unnamed for 15 frames, the free points fitting the shins within
        1 cm one way and 9 cm the other). Here the two free points (sure, or 2-view with one
        view missing them at ``unexplained_m`` more) are named when that pairing fits the shins,
        the lower marker below, the left one not right of the right one by ``crossed_m``, and
        every other pairing of free points costs ``shins_margin_m`` more. With two cameras
        ghosts fit shins as easily: three needed. assign, arow (8,) in place."""
        cfg = self.config
        if self._facing is None or len(self.rig) < 3 or cfg.shins_margin_m == float("inf"):
            return
        right = right_of(self._facing)
        for ends, anchors, below in (((LA, RA), (LK, RK), True), ((LK, RK), (LA, RA), False)):
            if (assign[list(ends)] >= 0).any() or (assign[list(anchors)] < 0).any():
                continue
            free = _recoverable(pts, assign)
            if len(free) < 2:
                return
            X = pts.X[free]
            A = pts.X[assign[list(anchors)]]  # (2, 3) left, right
            e = np.abs(np.linalg.norm(X[:, None] - A[None], axis=2) - self._body.shin)  # (P, 2)
            lower = (X[:, None, 2] < A[None, :, 2]) if below else (X[:, None, 2] > A[None, :, 2])
            doubt = np.where(pts.n_views[free] < 3, cfg.unexplained_m * pts.unexplained[free], 0.0)
            cost = np.where((e <= self._body.tol) & lower, e + doubt[:, None], np.inf)
            pairing = cost[:, :1] + cost[:, 1]  # (P, P) m: the left end on point i, the right one on j
            np.fill_diagonal(pairing, np.inf)
            best, runner_up = np.sort(pairing, axis=None)[:2]
            if not np.isfinite(best) or runner_up - best < cfg.shins_margin_m:
                continue
            i, j = np.unravel_index(int(np.argmin(pairing)), pairing.shape)
            if float((X[j] - X[i]) @ right) < -cfg.crossed_m:
                continue
            named = _named_on(pts, assign)
            named[list(ends)] = X[[i, j]]
            if self._body.violations(named):
                continue
            log.debug("t=%.3f s: markers %s found again on the points that fit the shins", self._t_frame, ends)
            _name_points(assign, arow, row_pt, ends, (int(free[i]), int(free[j])))

    def _recover_legs(self, pts: Points3D, pred: np.ndarray, assign: np.ndarray, arow: np.ndarray, row_pt: np.ndarray,
                      right: np.ndarray) -> None:
        """Both legs unnamed, the upper body named (after a blackout the identification can
        leave the legs of a subject climbing down out: named by no prediction, no anchor): the
        legs are found again as the only two disjoint pairs of free points that each fit a leg
        (a shin apart, knee above ankle or the shin level, within the rigid distances of the
        named markers), the left leg the one whose knee is to the subject's left, by at least
        ``crossed_m`` (knees side by side or crossed leave it unclear: nothing is named); a
        level shin's ends by :meth:`_one_fit`. pred (8, 3) m: the markers' predictions;
        assign, arow (8,) in place; right (3,) the subject's right."""
        body = self._body
        named, pairs = self._free_shins(pts, assign)
        fits = []
        for x in range(len(pairs)):
            for y in range(x + 1, len(pairs)):
                (k1, a1), (k2, a2) = pairs[x], pairs[y]
                if len({k1, a1, k2, a2}) < 4:
                    continue
                (lk, la), (rk, ra) = ((k1, a1), (k2, a2)) if float(pts.X[k1] @ right) < float(pts.X[k2] @ right) \
                    else ((k2, a2), (k1, a1))
                if float((pts.X[rk] - pts.X[lk]) @ right) < self.config.crossed_m:
                    continue  # knees side by side or crossed: which leg is which is not clear
                trial = named.copy()
                trial[[LK, LA, RK, RA]] = pts.X[[lk, la, rk, ra]]
                if not body.violations(trial):
                    fits.append((lk, la, rk, ra))
        fit = self._one_fit(pts, pred, fits, (LK, LA, RK, RA))
        if fit is not None:
            log.debug("t=%.3f s: both legs found again as the one pair of shins that fits them", self._t_frame)
            _name_points(assign, arow, row_pt, (LK, LA, RK, RA), fit)

    def _one_fit(self, pts: Points3D, pred: np.ndarray, fits: list[tuple[int, ...]],
                 markers: tuple[int, ...]) -> tuple[int, ...] | None:
        """The fit to name a leg's or both legs' markers (knee, ankle[, knee, ankle]) by: fits
        (point per marker) that all put the same points on the same legs, differing only in
        which end of a level shin is the knee (:meth:`_free_shins`), make one; of them, the one
        nearest the markers' predictions pred (8, 3) m from tracks named within
        ``track_timeout`` (else the knees highest).
        Case, seed 636 005_16: a dancer's leg whipped back level (ankle 8 cm above the knee,
        the feet 10-25 cm a frame) outran every leg's gate; found again with the knee taken as
        the higher end, the knee and ankle were swapped for 0.4 s. None when the fits differ in
        their points, or there are none."""
        legs = {tuple(frozenset(f[i:i + 2]) for i in range(0, len(f), 2)) for f in fits}
        if len(legs) != 1:
            return None
        if len(fits) == 1:
            return fits[0]
        m = np.array(markers)
        recent = (self._t_frame - self._seen[m] <= self.config.track_timeout) & np.isfinite(pred[m]).all(axis=1)
        if recent.any():
            return min(fits, key=lambda f: float(np.linalg.norm(pts.X[list(f)] - pred[m], axis=1)[recent].sum()))
        return max(fits, key=lambda f: float(sum(pts.X[f[i], 2] - pts.X[f[i + 1], 2] for i in range(0, len(f), 2))))

    def _free_shins(self, pts: Points3D, assign: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """The named markers (8, 3) (NaN = unnamed) and the (knee, ankle) candidates among the
        points nobody took (assign (8,): point per marker, -1 = none): pairs of point indices a
        shin apart (within the tolerance), the knee above, or below by at most
        ``ANKLE_ABOVE_M`` (a shin held level comes both ways round). Few, so clutter costs
        little."""
        free = _unnamed(len(pts), assign)
        named = _named_on(pts, assign)
        X = pts.X[free]
        shin_ok = (np.abs(np.linalg.norm(X[:, None] - X[None], axis=2) - self._body.shin) <= self._body.tol) & \
            (X[:, None, 2] > X[None, :, 2] - ANKLE_ABOVE_M)
        return named, [(int(free[i]), int(free[j])) for i, j in zip(*np.nonzero(shin_ok))]

    def _swap_for_shins(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray, right: np.ndarray | None) -> None:
        """Both shins (knee-ankle distances) broken while all four leg markers are named on
        points of their own, one by the tolerance, the other by ``shin_swap_min`` of it, and
        mended by swapping one pair: that pair was swapped (feet parting from a merged point the
        wrong way round). One broken shin beside a good one is a bad point (a knee point off
        for a frame), not a swap, unless the swap mends it and fits both shins within
        ``shin_mend_max`` of the tolerance (a standing ankle between the knees is a shin from
        both: a swap of the ankles breaks one shin only; >= 3 cameras). Swapping the knees or
        the ankles makes the same two shins, so which pair is wrong comes from the knees' order
        along the subject's right (3,): knees named crossed are the swapped pair (thighs hardly
        cross, feet often do), else the ankles. Not while a leg is on a point that may lie
        between two markers (:func:`_between`: a kneeling child's hidden knees made a 2-view
        point 11 cm off one of them from their merged blobs; tracking named a knee on it, both
        shins broke and the ankles, named right, were swapped: seed 3 005_12 at x0.75).
        out (8, 3), assign, arow (8,) in place; nothing when right is None."""
        if right is None or not _legs_apart(assign):
            return
        body = self._body
        named, mended = _shin_errors(body, out)
        errs = sorted(named)
        both_broken = errs[0] > self.config.shin_swap_min * body.tol and max(mended) <= body.tol
        # one broken shin mended: with two cameras a ghost point breaks a shin as often (a
        # hip-width 2-camera dance fell 42 -> 17 %), so it needs three
        one_mended = len(self.rig) >= 3 and max(mended) <= self.config.shin_mend_max * body.tol
        if errs[1] <= body.tol or not (both_broken or one_mended):
            return
        if self._pts is not None and _between(self._pts, assign)[[LK, RK, LA, RA]].any():
            return
        pair = _swapped_pair(out, right)
        log.debug("t=%.3f s: %s swapped: %s, swapped both fit", self._t_frame, pair,
                  "both shins broken" if both_broken else "one shin broken")
        self._swap([pair], out, assign, arow)

    def _cross_for_shins(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray, right: np.ndarray | None,
                         t: float) -> None:
        """Legs named on four points of their own whose shins (knee-ankle distances) fit
        ``cross_gain_m`` better with the ankles' names swapped, both within ``cross_fit`` of the
        tolerance, for ``cross_s``: the feet are crossed and were named side by side. Nothing
        else crosses names: the identification and the skeleton's prediction both put the left
        foot on the left, and a dancer holding a pose on one foot with the other raised across it
        (knees apart, feet 30 cm apart the other way round) kept her ankles named the wrong way
        round for 3.5 s, tight fits that no bound flags. The knees keep their order (thighs
        hardly cross, feet often do), unless they are named crossed: then they swap. Three
        cameras or more (with two, ghost points break shins as often), and the subject measured
        (a child's feet together, 12 cm apart, fit an adult's shin better crossed). Frames where
        the check cannot be made (a leg marker unnamed, or on a merged point), at most ``cross_s``
        since the last that could, neither break nor count against the hold: a knee hidden every
        few frames restarted it, so that it never held (traced on a dance from 8 s on another
        body, 005_18). out (8, 3), assign, arow (8,) in place."""
        holds = False
        if right is not None and len(self.rig) >= 3 and self._body.measured and _legs_apart(assign):
            named, crossed = _shin_errors(self._body, out)
            holds = max(crossed) <= self.config.cross_fit * self._body.tol and \
                sum(named) - sum(crossed) >= self.config.cross_gain_m
            self._cross_seen = t
        elif self._cross_since is not None and t - self._cross_seen <= self.config.cross_s:
            return  # the legs not all named on points of their own this frame: the hold goes on
        since = self._cross_since = _held_since(self._cross_since, holds, t)
        if since is not None and t - since >= self.config.cross_s:
            pair = _swapped_pair(out, right)
            log.debug("t=%.3f s: %s swapped: the shins fit %.2f s better crossed", t, pair, t - since)
            self._cross_since = None
            self._swap([pair], out, assign, arow)

    def _swap_arms(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray, t: float) -> None:
        """A hand that rested on its shoulder (one merged point) parts from it with the names the
        wrong way round as often as not, and tracking keeps them so. The shoulders are rigid: a
        shoulder named more than half the tolerance off the shoulder width from the other one,
        while its own wrist's point is within a sixth of it and level with the other shoulder
        (``LEVEL_M``), for ``arm_swap_s``, swaps names (and tracks) with that wrist. out (8, 3),
        assign, arow (8,) in place."""
        body = self._body
        for i, (s, w, o) in enumerate(_ARMS):
            fits = assign[s] >= 0 and assign[w] >= 0 and assign[o] >= 0 and \
                len({int(assign[s]), int(assign[w]), int(assign[o])}) == 3 and \
                body.width_error(out[s], out[o]) > 0.5 * body.tol and \
                body.width_error(out[w], out[o]) < body.tol / 6 and abs(float(out[w, 2] - out[o, 2])) <= LEVEL_M
            since = self._arm_swap_since[i] = _held_since(self._arm_swap_since[i], fits, t)
            if since is not None and t - since >= self.config.arm_swap_s - 1e-6:
                log.debug("t=%.3f s: shoulder %d and its wrist swapped: the wrist's point fits the shoulder width", t, s)
                self._arm_swap_since[i] = None
                self._swap([(s, w)], out, assign, arow)

    def _wrists_by_reach(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray) -> None:
        """Two hands together (on a sword hilt, a clap) merge in the views and part with their
        names either way round; named on points of their own they fit no rigid length better
        one way than the other, until the arms stretch: a wrist beyond its arm's reach of its
        shoulder (by ``reach_swap_m``) while the other naming puts both wrists within reach (by
        ``reach_fit_m``) is the swap, and the names (and tracks) are swapped. Only with the
        subject measured. out (8, 3), assign, arow (8,) in place."""
        cfg = self.config
        body = self._body
        if not body.measured or not (assign[[LS, RS, LW, RW]] >= 0).all() or assign[LW] == assign[RW]:
            return
        def beyond(lw: int, rw: int) -> float:  # the farther wrist's excess over the reach (m)
            return max(float(np.linalg.norm(out[lw] - out[LS])), float(np.linalg.norm(out[rw] - out[RS]))) - body.reach
        if beyond(LW, RW) > cfg.reach_swap_m and beyond(RW, LW) < -cfg.reach_fit_m:
            log.debug("wrists swapped: one was %.3f m beyond its reach", beyond(LW, RW))
            self._swap([(LW, RW)], out, assign, arow)

    def _swap_to_fit(self, out: np.ndarray, pred: np.ndarray, assign: np.ndarray, arow: np.ndarray,
                     t: float) -> None:
        """The names are compared with the motion database (``pose_fit``) against each
        confusion tracking can make (a wrist and its shoulder, the two wrists, knees or ankles, a
        knee and its ankle, a wrist and the other shoulder, the upper body's mirror image, the
        mirror image) of markers named
        on points: a swap that brings the markers within ``fit_swap_ratio`` of their
        distance to the nearest body, the same swap at every check (each ``fit_interval``) for
        ``fit_swap_s``, is made (names and tracks). Unnamed markers stand at their predictions
        pred (8, 3) for the comparison (none without one). A hand passing its shoulder can leave the two names the
        other way round, each a plausible distance from the other markers, so no rigid length
        tells; the pose they make (a shoulder in front of the chest, the arm folded through it)
        is one no body in the database takes. Not both legs at once: that swap keeps every shin
        and every leg on its side within ``crossed_m``, so only the database would tell, and a
        subject standing with crossed ankles (no database body does) fits it better swapped (a
        dancer on another body, 005_13 seed 11, was so renamed in both passes: 1.7 s with both
        legs' names wrong); the solver's verdict (:meth:`refit`) still tries it. out (8, 3),
        assign, arow (8,) in place."""
        cfg = self.config
        if t - self._t_fit < cfg.fit_interval - 1e-6:
            return
        self._t_fit = t
        base = np.where((assign >= 0)[:, None], out, pred)
        if self.pose_fit is None or not math.isfinite(cfg.fit_swap_s) or not np.isfinite(base).all():
            self._fit_swap = None
            return
        swappable = self._swappable(assign >= 0, t)
        swappable[_LEGS] = False
        usable = np.flatnonzero(swappable)
        dist0 = float(self.pose_fit(base[None])[0])
        best, holds = -1, False
        if usable.size and math.isfinite(dist0):
            # only swaps that fit clearly better are looked for (a bound the search prunes with)
            dist = self.pose_fit(base[_FIT_SWAPS[usable]], cfg.fit_swap_ratio * dist0)
            i = int(np.argmin(dist))
            best, holds = int(usable[i]), bool(dist[i] < cfg.fit_swap_ratio * dist0)
        if not holds or self._fit_swap is None or self._fit_swap[0] != best:
            self._fit_swap = (best, t) if holds else None
        if self._fit_swap is not None and t - self._fit_swap[1] >= cfg.fit_swap_s - 1e-6:
            perm = _FIT_SWAPS[best]
            pairs = [(m, int(perm[m])) for m in range(N_MARKERS) if perm[m] > m]
            log.debug("t=%.3f s: names %s swapped: %.3f m from a database body, %.3f as they were", t, pairs,
                      dist[i], dist0)
            self._fit_swap = None
            self._swap(pairs, out, assign, arow)

    def _swappable(self, named: np.ndarray, t: float) -> np.ndarray:
        """(len(_FIT_SWAPS),) bool: the confusions worth trying on names given to points (named
        (8,) bool; an unnamed marker's prediction is not a name). The mirror image turns the
        subject round in one frame: only a fresh identification (``fit_mirror_s``) can have got
        that wrong, not names tracked since (a straight leg raised 45 degrees in front lies
        nearer a database body named as the other leg stretched behind, and was so renamed).
        The upper body's mirror image (shoulders and wrists) only outside that window. With two
        cameras the mirror image is always tried, the upper body's never."""
        ok = ~(_FIT_MOVES & ~named).any(axis=1)
        # with two cameras mirrored identifications are common and the fit mends them later
        # (three 2-camera benchmark takes lost 2.6-8 points with the window)
        identified = t - self._t_identified <= self.config.fit_mirror_s or len(self.rig) < 3
        ok[_MIRROR] &= identified
        # the upper body's mirror where the whole one is not: there a mirrored identification is
        # the likely mistake, and the upper mirror, as near a body as the whole one for a subject
        # standing, left the legs mirrored (005_19 seed 649, a fresh body back from a blackout
        # identified mirrored: the legs named for each other for the last 2.7 s)
        ok[_UPPER_MIRROR] &= not identified
        return ok

    def _uncross_knees(self, out: np.ndarray, assign: np.ndarray, arow: np.ndarray, right: np.ndarray,
                       t: float) -> None:
        """Knees named crossed (the right one ``crossed_m`` left of the left one, right (3,) the
        subject's right) for ``knees_crossed_s`` are the two legs' names swapped: a crossover step
        or a dancer's crossed feet cross the ankles, the thighs hardly ever cross for long (on
        the CMU clips' true poses knees crossed by 6 cm for at most 0.63 s, 0.5 % of frames; the
        ankles for 19 %). A swapped leg pair keeps its shins and nothing else catches it: a
        dancer's feet part from a merged point the other way round and the knees follow. The
        legs' names are swapped back (knee and ankle together). out (8, 3), assign, arow (8,) in place."""
        if assign[LK] < 0 or assign[RK] < 0 or assign[LK] == assign[RK]:
            return
        crossed = float((out[RK] - out[LK]) @ right) < -self.config.crossed_m
        since = self._knees_crossed_since = _held_since(self._knees_crossed_since, crossed, t)
        if since is not None and t - since >= self.config.knees_crossed_s:
            log.debug("t=%.3f s: knees crossed for %.2f s: the legs' names swapped", t, t - since)
            self._knees_crossed_since = None
            self._swap(list(_LEG_PAIRS), out, assign, arow)

    def _swap(self, pairs: list[tuple[int, int]], *frame: np.ndarray) -> None:
        """Swap the names of each (m, n) marker pair: in the frame's arrays (out (8, 3), assign,
        arow (8,)) in place, and the tracks (position, velocity, last seen) with them, so their
        velocities carry on."""
        for m, n in pairs:
            self._renamed |= (1 << m) | (1 << n)
            for a in (*frame, self._pos, self._vel, self._seen):
                a[[m, n]] = a[[n, m]]

    def _unglue(self, out: np.ndarray, assign: np.ndarray, t: float) -> None:
        """A wrist that took a shoulder's point (the hand passed its shoulder, or was held on
        the other one) stays there, rigidly a shoulder width from the other shoulder, while
        that shoulder stays unnamed; a hand does that for a moment, a shoulder always. Either
        wrist may be the one (the one nearest a shoulder width from the other shoulder). After ``glued_wrist_s`` of it (within
        3 cm of the measured width, spread <= 1 cm, within 10 cm of the other shoulder's height) the
        point is renamed the shoulder and the wrist's track dropped (the skeleton predicts it).
        On the CMU clips a true wrist met this in 12 of 46 798 windows, each time within 20 cm of
        its own shoulder. out (8, 3), assign (8,) in place."""
        cfg = self.config
        named = np.isfinite(out).all(axis=1)
        for side, (S, _own, O) in enumerate(_ARMS):
            hist = self._glue[side]
            wrists = [w for w in (LW, RW) if named[w]]
            if not (wrists and named[O] and not named[S]):
                hist.clear()
                continue
            # either wrist: a hand held on the other side's shoulder takes its point too
            dist = {w: float(np.linalg.norm(out[w] - out[O])) for w in wrists}
            W = min(wrists, key=lambda w: abs(dist[w] - self._body.shoulder_width))
            if hist and hist[-1][3] != W:
                hist.clear()
            hist.append((t, dist[W], float(out[W][2] - out[O][2]), W))
            while hist and t - hist[0][0] > cfg.glued_wrist_s + 1e-6:
                hist.pop(0)
            if t - hist[0][0] < cfg.glued_wrist_s - 0.02:
                continue
            d = np.array([h[1] for h in hist])
            dz = np.array([h[2] for h in hist])
            if self._body.measured and (np.abs(d - self._body.shoulder_width) <= 0.03).all() and \
                    d.std() <= 0.01 and (np.abs(dz) <= 0.1).all():
                log.debug("t=%.3f s: a wrist held a shoulder width from the other shoulder for %.2f s: "
                          "renamed its shoulder", t, t - hist[0][0])
                out[S], out[W] = out[W], np.nan
                self._renamed |= (1 << S) | (1 << W)
                assign[S], assign[W] = assign[W], -1
                self._seen[W] = -np.inf
                self._pos[W] = np.nan
                hist.clear()

    def _hint(self, t: float) -> Hint:
        """What identification may assume at time t: the last facing (trusted less the longer
        ago; ``first_facing`` before any labelling) and the body's travel (in true time)."""
        cfg = self.config
        hint = Hint()
        if self._facing is not None:
            hint.facing = self._facing
            hint.facing_weight = cfg.facing_weight * math.exp(-(t - self._t_facing) / cfg.facing_decay)
            hint.facing_slack = min(math.pi / 2, cfg.facing_turn_rate * (t - self._t_facing))
        elif self.stats.identifications == 0:
            hint.facing, hint.facing_weight = np.array(cfg.first_facing, float), cfg.first_facing_weight
        if len(self._centres) >= 2 and self._centres[-1][0] - self._centres[0][0] >= 0.2:
            (t0, c0), (t1, c1) = self._centres[0], self._centres[-1]
            # backwards in time a subject walking forwards walks backwards
            hint.velocity = (c1 - c0) / (t1 - t0) * (-1.0 if cfg.time_reversed else 1.0)
        return hint

    def _crossed_before(self, t: float) -> tuple[bool, bool]:
        """(knees, ankles): the pair was last named crossed, the right one more than ``crossed_m``
        left of the left one along the last facing, within ``crossed_memory_s`` before t. A
        dancer standing on one foot with the other pointed out behind and across it holds the
        pose through a blackout; "the left leg on the left" made the identification name her
        legs mirrored, or leave them to a skeleton that did."""
        cfg = self.config
        if self._facing is None:
            return False, False
        right = right_of(self._facing)
        out = []
        for lm, rm in _LEG_PAIRS:
            recent = t - min(self._seen[lm], self._seen[rm]) <= cfg.crossed_memory_s
            known = recent and np.isfinite(self._pos[[lm, rm]]).all()
            out.append(bool(known and float((self._pos[rm] - self._pos[lm]) @ right) < -cfg.crossed_m))
        return out[0], out[1]

    @staticmethod
    def _trust(pts: Points3D, standard: bool = False) -> np.ndarray:
        """(M,) identification penalty per point: 0 from >= 3 views, else for the views that missed
        it; standard (the subject not measured yet: the standard pose), not for the views where
        it is hidden behind a point seen by >= 3 views (``Points3D.behind``: the far knee seen
        from the side; later a ghost between two hands on a hilt falls there too)."""
        missed = pts.unexplained
        if standard and pts.behind is not None:
            missed = missed - pts.behind
        return np.where(pts.n_views >= 3, 0.0, np.minimum(0.9 * missed, 2.0))

    def _fitted(self, t: float) -> bool:
        """The solver fitted the names of the frame before t s within ``audit_fit_m`` (rms), with
        >= 3 cameras: names a body fits that well are not moved by an identification. Its
        anatomy has knees below the shoulders; a dancer's kick lifted a tracked ankle above
        them, and an audit moved the shoulders and wrists onto the kicking leg and an arm
        (005_05 on a x1.25 body, 0.08 cm rms before: 40-63 cm off until the blackout)."""
        t_fit, residual = self._fit
        return len(self.rig) >= 3 and t - t_fit <= self.config.track_timeout and \
            residual <= self.config.audit_fit_m

    def _audit(self, pts: Points3D, tracked_out: np.ndarray, assign: np.ndarray, q: LabelQuality,
               t: float) -> tuple[np.ndarray, LabelQuality, np.ndarray | None] | None:
        """Check the tracked names of this frame against a fresh identification, every
        ``audit_interval`` s while a point that is surely a marker (>= 3 views, or no view
        missing it) and not a static reflection stays unnamed: tracking that went wrong (a
        wrist that took its shoulder's point, a leg named for the other) keeps itself wrong, a
        fresh look does not. The identification, which counts each name it shares with
        tracking as evidence (``audit_agree``), replaces the tracked names when it is clear
        (``min_margin`` over every rival) and scores ``audit_margin`` more than they do
        (``audit_extend_margin`` when it only adds names: a wrist whose track and skeleton lost
        it), or names >= 2 more markers where the tracked names lack a shoulder (as many, naming
        both shoulders, when one has been unnamed ``audit_shoulder_lost_s``); never one that
        moves >= 2 tracked names (naming < 2 more) the solver fitted well (:meth:`_fitted`).
        An unclear identification (margin < ``min_margin``) is judged the same way, but replaces
        only the names its close rivals agree on (:meth:`_agreed`).
        tracked_out: (8, 3) the tracked names; assign: (8,) their points (-1 = unnamed). Returns
        (8, 3) markers, quality and (8,) bool the markers whose tracks go on (None: all
        restart), or None."""
        cfg = self.config
        free = _unnamed(len(pts), assign)
        free = free[(pts.n_views[free] >= 3) | (pts.unexplained[free] == 0)]
        self._free_hist = [h for h in self._free_hist if t - h[0] <= 1.0] + [(t, pts.X[free])]
        if not math.isfinite(cfg.audit_interval) or t - self._t_audit < cfg.audit_interval or \
                len(pts) < cfg.min_points or not self._moving(pts.X[free], t).any():
            return None
        shoulder_lost = [t - self._seen[s] for s in (LS, RS) if assign[s] < 0]
        if shoulder_lost and min(shoulder_lost) < cfg.audit_shoulder_s and len(self.rig) >= 3:
            # a shoulder unnamed for a frame or two (its point missing: a raised hand's blob
            # over it made a ghost instead) comes back to tracking; identified afresh on that
            # frame's points, the names shifted onto the ghost and stayed wrong for 0.4 s. With
            # two cameras the fresh look mends more than it breaks (three takes lost 20-30
            # points of the 2-camera benchmark with the wait, one gained 28)
            return None
        self._t_audit = t
        self.stats.audits += 1
        trust = self._trust(pts)
        hint = self._hint(t)
        hint.labels, hint.labels_weight = assign, cfg.audit_agree
        hyps = identify(pts.X, trust, self._body, hint, shared=pts.merged_all)
        if not hyps:
            return None
        best = hyps[0]
        margin = _margin(best.labels, best.score, hyps[1:])
        unclear = margin < cfg.min_margin
        if unclear:
            best = self._agreed(hyps, assign)
            if best is None:
                return None
            margin = max(0.0, _margin(best.labels, best.score, hyps[1:]))
        extends = not (_disputed(assign, [best]) & (assign >= 0)).any()
        if extends and np.count_nonzero(best.labels >= 0) <= np.count_nonzero(assign >= 0):
            return None
        tracked = score_labels(pts.X, trust, self._body, hint, assign, pts.merged_all)
        # names moved from the point tracking gave them to another one, without naming two more
        # markers (a leg named on the other leg moves two names and names the other two)
        moved = int(np.count_nonzero((assign >= 0) & (best.labels >= 0) & (best.labels != assign)))
        gained = int(np.count_nonzero(best.labels >= 0)) - int(np.count_nonzero(assign >= 0))
        # moving names (>= 2 of them without naming two more, or any while all eight are named
        # on points: then a free sure point is a ghost or a reflection, not a lost marker)
        complete = bool((assign >= 0).all())
        if moved >= 2 and gained < 2 and self._fitted(t):
            return None
        need = cfg.audit_extend_margin if extends else \
            (cfg.audit_move_margin if (moved >= 2 and gained < 2) or complete else cfg.audit_margin)
        if tracked is None:
            # tracked names lacking a shoulder for long give way to a clear identification
            # naming both and as many markers: a dancer's leg kicked up to her shoulders was
            # named a shoulder after a blackout, and the names stayed wrong for 5 s
            # (>= 3 cameras, as the wait above: with two, not measured)
            long_lost = len(self.rig) >= 3 and max(shoulder_lost, default=0.0) >= cfg.audit_shoulder_lost_s and \
                bool((best.labels[[LS, RS]] >= 0).all())
            n_best = int(np.count_nonzero(best.labels >= 0))
            if n_best < q.n_labelled + 2 and not (long_lost and n_best >= q.n_labelled):
                return None
        elif best.score - tracked < need:
            return None
        self.stats.audit_switches += 1
        if not extends:  # the names taken from the points tracking gave them
            self._renamed = marker_bits((assign >= 0) & (best.labels != assign))
        log.debug("t=%.3f s: tracked names replaced by an identification (score %.2f over %s)", t, best.score,
                  "no shoulders" if tracked is None else f"{tracked:.2f}")
        out = self._named(pts, best.labels, best.facing)
        if extends:  # the tracked names stay as tracked (a shared point's split included)
            keep = np.isfinite(tracked_out).all(axis=1)
            out[keep] = tracked_out[keep]
            q.n_labelled = int(np.isfinite(out).all(axis=1).sum())
            return out, q, keep
        kept = None
        if unclear:  # the names it kept from tracking stay as tracked, and so do their tracks
            kept = (best.labels == assign) & (assign >= 0)
            out[kept] = tracked_out[kept]
        return out, LabelQuality(int(np.count_nonzero(best.labels >= 0)), len(pts), 0.1 * margin, 0.0,
                                 "identified", 0), kept

    def _agreed(self, hyps: list, assign: np.ndarray) -> Hypothesis | None:
        """An unclear audit's labelling (the best of hyps scores less than ``min_margin`` over a
        rival): the names every hypothesis within ``min_margin`` of the best agrees on, but
        none on a point a tracked name keeps; for the other markers (disputed, or left unnamed:
        an unclear look drops no name) the tracked names assign (8,) (-1 = unnamed). With the
        best's score (how much a fresh look beats the tracking); None when that labelling is
        the tracked one. Case, seed 635 002_04 (knees merged in three views): the hidden right
        ankle was tracked onto the right knee's point, the knee unnamed; when the ankle's own
        point came back (4 views), every close identification named it there but the knees'
        order was unclear (margin 0.4), and the ankle stayed on the knee's point for 0.7 s."""
        best = hyps[0]
        close = [h for h in hyps[1:] if best.score - h.score < self.config.min_margin]
        labels = best.labels.copy()
        disputed = _disputed(best.labels, close)
        labels[disputed] = -1
        keep = (labels < 0) & (assign >= 0) & ~np.isin(assign, labels[labels >= 0])
        labels[keep] = assign[keep]
        for _ in range(N_MARKERS):  # (a marker moved back may leave another unnamed: again)
            lost = np.flatnonzero((assign >= 0) & (labels < 0))
            if not lost.size:
                break
            for m in lost:
                # a tracked name's point given to another marker goes back to it (a dancer's
                # hand on her knee: the wrist was named on the knee's point, the knee left
                # unnamed, the legs then named swapped for 1.5 s by the backward pass, 636 005_06)
                for n in np.flatnonzero((labels == assign[m]) & (assign != assign[m])):
                    labels[n] = assign[n] if assign[n] >= 0 and not np.isin(assign[n], labels).any() else -1
                labels[m] = assign[m]
        return None if np.array_equal(labels, assign) else Hypothesis(labels, best.score, best.facing)

    def _moving(self, X: np.ndarray, t: float) -> np.ndarray:
        """(F,) bool per free sure point X (F, 3): not a static reflection, i.e. not within 2 cm
        of a free point 0.5 to 1 s ago, every 0.1 s (a marker is named or moves)."""
        old: list[tuple[float, np.ndarray]] = []
        for ht, Y in self._free_hist:
            if t - ht >= 0.5 and (not old or ht - old[-1][0] >= 0.1 - 1e-6):
                old.append((ht, Y))
        if len(old) < 3:
            return np.ones(len(X), bool)
        static = np.ones(len(X), bool)
        for _ht, Y in old:
            if not len(Y):
                return np.ones(len(X), bool)
            static &= _nearest(X, Y) <= 0.02
        return ~static

    def _split_shared(self, out: np.ndarray, assign: np.ndarray, pts: Points3D, pred: np.ndarray,
                      right: np.ndarray | None) -> None:
        """Markers named to the same (merged) point: place them either side of it, by the guess
        of :func:`_guess_split`, or by their separation measured from the merged blobs' moments
        (:meth:`_measured_split`, that guess as its prior): the two knees or the two ankles
        (``split_legs_sigma_px``) where it lies within ``split_legs_max_deg`` of the guess, the two
        wrists (``split_wrists_sigma_px``), other pairs opt-in (``split_sigma_px``). Two wrists
        (hands together) are guessed along their tracks' predictions, which carry the hands' last
        separation and motion (one above the other on a sword hilt, crossing over each other in a
        dance), and along the subject's right only when those coincide; the moments then measure
        the separation, that guess giving its sign, so a turning hilt is followed frame by frame:
        the names the hands part with come from this split. A knee and the other leg's ankle (a
        foot kicked back behind the other knee) are split along their predictions only for
        ``split_share_s`` after they met on the point, then both stay on it: their tracks, split
        from it frame after frame, keep the direction they met in while the legs turn. Two
        knees or ankles named crossed in the frame before (by ``split_crossed_m``) and now placed
        uncrossed are renamed (:attr:`LabelQuality.renamed`): each name moves to the
        other's marker, as a swap rule would move it, and the offline choice
        (:mod:`samba_server.both_ways`) doubts the names before, as after any rename (a
        dancer's legs named the mirror way round after a blackout, mended so 0.6 s later).
        With two cameras the wrists' tracks are too often on ghosts: :meth:`_wrists_split`
        chooses. out (8, 3) in place; assign (8,) point per marker (-1: none); pred (8, 3) the
        markers' predictions; right (3,) the subject's right or None."""
        cfg = self.config
        named = assign[assign >= 0]
        if len(set(named.tolist())) == len(named):  # no point named twice
            return
        named = np.unique(named)
        for p in named:
            ms = np.flatnonzero(assign == p)
            if len(ms) != 2:
                continue
            m, n = ms
            wrists = (m, n) == (LW, RW)
            legs = (m, n) in _LEG_PAIRS
            in_line = self._in_line(m, n, right) if legs and right is not None and len(self.rig) >= 3 else None
            off = in_line if in_line is not None else _guess_split(pred, m, n, cfg.merged_half_m, None if wrists else right)
            if in_line is not None:
                self._lined.add((m, n))
            if wrists and (off is None or len(self.rig) < 3):
                lateral = _guess_split(pred, m, n, cfg.merged_half_m, right)
                # (with right None the two guesses are one: lateral is None only when off is)
                off = lateral if off is None else self._wrists_split(out, pred, lateral, off)
            if off is None:  # no way to tell which end is which: both stay on the point
                continue
            if self._t_frame - self._sharing.get((m, n), self._t_frame) > cfg.split_share_s:
                continue  # their predictions, split from this point for a while, say no more where they are
            if legs and right is not None and self._crossed_last(m, n, right):
                self._renamed |= (1 << m) | (1 << n)  # named crossed, placed uncrossed: renamed
            measured = self._measured_split(pts, int(p), 2.0 * off, named,
                                            cfg.split_legs_sigma_px if legs else
                                            cfg.split_wrists_sigma_px if wrists else cfg.split_sigma_px)
            if measured is not None and legs:
                if _angle_deg(measured, off) > cfg.split_legs_max_deg:
                    measured = None  # legs one before the other: which knee is which end is a coin flip
                else:
                    # only its length along the guess: the part across it (one leg a little
                    # before the other) has a sign that neither the views nor the guess tell
                    u = off / np.linalg.norm(off)
                    measured = float(measured @ u) * u
            if measured is not None:
                off = 0.5 * measured
            out[m] = out[m] + off
            out[n] = out[n] - off

    def _in_line(self, m: int, n: int, right: np.ndarray) -> np.ndarray | None:
        """Half the separation (3,) m, at most ``merged_half_m``, of the two knees (or ankles)
        m, n where they were named in the frame before, when both were named there on points of
        their own that were not loose (:meth:`loose`; or split so by this rule), not crossed
        (:meth:`_crossed_last`: a pair the split across the body uncrosses, a rename), at least
        ``split_in_line_m`` apart in a direction more than ``split_legs_max_deg`` off the
        subject's right (3,): one before the other, as in a step, where the guess across the body
        would put both beside their merged point and leave which is which to chance the next
        frame (a walk's ankles, 15 cm one before the other and merged in every view for a frame,
        swapped there; 005_17 seed 638). Else None. Their named places, not the predictions:
        velocities taken from rough points predicted a standard pose's merged knees one before
        the other (006_02 seed 638); and only firm ones: knees side by side named on two
        mirrored points 8 cm off, one before the other, were split so (002_04 seed 638). Split
        so, the two stay one before the other through a merge of several frames. With three
        cameras or more (measured there; with two, whose points are often ghosts, the 2-camera
        benchmark's checked set lost 0.2 point: the guess across the body stays)."""
        cfg = self.config
        if not (self._seen[[m, n]] >= self._t_prev - 1e-6).all() or self._crossed_last(m, n, right):
            return None
        if (m, n) not in self._lined_prev:
            named, pts = self._named_prev
            if pts is None or not np.isfinite(named[[m, n]]).all() or self.loose(named, pts)[[m, n]].any():
                return None
        apart = self._pos[m] - self._pos[n]
        norm = float(np.linalg.norm(apart))
        if not np.isfinite(norm) or norm < cfg.split_in_line_m \
                or abs(float(apart @ right)) / norm >= math.cos(math.radians(cfg.split_legs_max_deg)):
            return None
        return _guess_split(self._pos, m, n, cfg.merged_half_m, None)  # along the named places

    def _crossed_last(self, m: int, n: int, right: np.ndarray) -> bool:
        """Whether the left marker m and the right one n were both named in the frame before,
        n at least ``split_crossed_m`` left of m along the subject's right (3,). (Their named
        places, not the predictions: two knees on a bad 2-view point, split there, had
        velocities that crossed the predictions of a pair named uncrossed. Less than the swap
        rules' ``crossed_m``: a dancer's knees, one before the other in a step, named the
        mirror way round after a blackout and 5-6 cm crossed when they met, were split
        uncrossed unreported, 0.5 s of wrong legs left unmended.)"""
        seen = self._seen[[m, n]] >= self._t_prev - 1e-6
        return bool(seen.all() and float((self._pos[n] - self._pos[m]) @ right) < -self.config.split_crossed_m)

    def _wrists_split(self, out: np.ndarray, pred: np.ndarray, lateral: np.ndarray,
                      tracked: np.ndarray) -> np.ndarray:
        """Two wrists on one point (hands together), two cameras: the left one's half separation
        (3,) m, either along the subject's right (``lateral``: hands side by side, as in a clap)
        or along their tracks' predictions (``tracked``: one hand above the other on a hilt),
        whichever puts the eight markers nearer a body of the motion database (``pose_fit``;
        unnamed markers at their predictions; along the subject's right without one). out, pred
        (8, 3)."""
        base = np.where(np.isfinite(out).all(axis=1)[:, None], out, pred)
        if self.pose_fit is None or not np.isfinite(base).all():
            return lateral
        cand = np.repeat(base[None], 2, axis=0)
        for i, off in enumerate((lateral, tracked)):
            cand[i, LW] += off
            cand[i, RW] -= off
        dist = self.pose_fit(cand)
        return tracked if float(dist[1]) < float(dist[0]) else lateral

    def _measured_split(self, pts: Points3D, p: int, prior: np.ndarray, named: np.ndarray,
                        sigma_px: float) -> np.ndarray | None:
        """The separation (3,) m of the two markers of point p from the moments of its merged
        blobs, when every view saw it merged (or in a blob of one marker's size whose moments
        part two by >= ``PointsConfig.elongated_px``: the two overlap) with measured moments, in
        blobs no other named point (named: the points markers are named to) uses, and they are
        >= ``split_min_views`` (else None: the point is not surely the two markers' midpoint, a
        blob holds a third marker, or the views leave a direction unmeasured). prior (3,) m: the
        guess, sign included; sigma_px: the moments' noise (inf: None, not measured)."""
        cfg = self.config
        if not np.isfinite(sigma_px):
            return None
        cams, seps = [], []
        for c, v in enumerate(self._views):
            b = int(pts.blob[c, p])
            if b < 0:
                continue
            if not np.isfinite(v.moments[b]).all():
                return None
            sep = blob_separation(v.moments[b])[0]
            if v.capacity[b] < 2 and np.hypot(*sep) < self.points.config.elongated_px:
                return None  # a view of one marker (not two overlapping): the point is not the two markers' midpoint
            if any(q != p and pts.blob[c, q] == b for q in named):
                return None  # another named point's blob too: it holds more than these two
            cams.append(c)
            seps.append(sep)
        if len(cams) < cfg.split_min_views:
            return None
        J = jacobians(lambda P: self.points.tri.project(P)[0], pts.X[p])[cams]
        return separation_3d(J, np.array(seps), prior, sigma_px, cfg.split_prior_m)

    def _named(self, pts: Points3D, labels: np.ndarray, facing: np.ndarray) -> np.ndarray:
        """(8, 3) markers at the points labels (8,) name (-1 = unnamed), a shared point split
        along the right of facing (2,)."""
        out = np.full((N_MARKERS, 3), np.nan)
        named = labels >= 0
        out[named] = pts.X[labels[named]]
        self._split_shared(out, labels, pts, np.zeros((N_MARKERS, 3)), right_of(facing))
        return out

    def _identify(self, pts: Points3D, t: float) -> tuple[np.ndarray, LabelQuality] | None:
        cfg = self.config
        if len(pts) < cfg.min_points:
            return None
        hint = self._hint(t)
        if len(self.rig) >= 3:  # with two, ghosts cross legs as often (a dance 43 -> 24 %)
            hint.crossed = self._crossed_before(t)
        trust = self._trust(pts, not self._body.measured)
        hint.labels, hint.labels_weight = self._recalled(pts, t), cfg.audit_agree
        hyps = identify(pts.X, trust, self._raised(pts), hint, shared=pts.merged_all)
        if not hyps:
            self._t_ambiguous = self._steady = None
            return None
        best = hyps[0]
        margin = best.score - hyps[1].score if len(hyps) > 1 else best.score
        labels = best.labels.copy()
        best_named = self._named(pts, best.labels, best.facing)  # (8, 3)
        prev, self._best_prev = self._best_prev, (t, best_named)
        if margin < cfg.min_margin:
            # name at once what every close runner-up agrees on (e.g. all but an ankle pair
            # whose order is unclear; with a shoulder on a point that may be a ghost, only if
            # the frame before's best labelling named them at the same places); the rest waits
            # for the tracking and the skeleton
            close = [h for h in hyps[1:] if best.score - h.score < cfg.min_margin]
            labels[_disputed(best.labels, close)] = -1
            partial = not ((labels[[LS, RS]] < 0).any() or np.count_nonzero(labels >= 0) < cfg.min_points)
            if partial and (trust[labels[[LS, RS]]] > 0).any():
                partial = self._agrees(prev, self._named(pts, labels, best.facing))
            if not partial:
                if self._t_ambiguous is None:
                    self._t_ambiguous = t
                steady = len(self.rig) >= 3 and t - self._steady_since(best_named, t) >= cfg.steady_s - 1e-6
                if t - self._t_ambiguous < cfg.max_wait and not steady:
                    return None
                labels = best.labels.copy()
        self._t_ambiguous = self._steady = None
        margin = _margin(labels, best.score, hyps[1:])
        out = self._named(pts, labels, best.facing)
        named = labels >= 0
        if not self._body.measured:  # the rules until the subject is measured: the prior at this size
            self._body = sized(self._prior, out[LS], out[RS], float(pts.X[:, 2].min()))
        self.stats.identifications += 1
        if self.stats.first_identified_t is None:
            self.stats.first_identified_t = t
        elif self._t_lost is not None:
            self.stats.reacquire_s.append(t - self._t_lost)
        self._t_lost = None
        log.info("t=%.3f s: markers identified from %d points (%d named, margin %.2f)", t, len(pts),
                 int(named.sum()), margin)
        return out, LabelQuality(int(named.sum()), len(pts), 0.1 * margin, 0.0, "identified", 0)

    def _recalled(self, pts: Points3D, t: float) -> np.ndarray:
        """(8,) per marker the point within ``recall_m`` of where it was last named, at most
        ``recall_s`` before t (-1 = none): evidence for identifying afresh. A subject kneeling
        still through a blackout, knees hidden and one foot before the other, came back where
        she was; the facing cannot tell which foot is which along it, and the close
        identifications left the ankles to the skeleton, which solved them swapped (seed 3
        005_12 at x0.75: the rest of the take, 4 s, the ankles' names swapped). A subject who
        turned in place comes back mirrored near where she was: that evidence (0.3 a marker)
        is less than a side-by-side pair's left-on-the-left, or the facing's. Only a point and
        a marker that are each other's only match count: hands together on a hilt come back
        with both wrists near both points, which says nothing of which is which. Three cameras
        or more: with two, whose 2-view ghosts lie anywhere near where markers were, a
        punching take (002_04) went from 9.4 % of frames right to none, 18.5 % of its
        confident frames confidently wrong (three other 2-camera takes gained 15-25 points)."""
        cfg = self.config
        out = np.full(N_MARKERS, -1, np.int64)
        recent = (t - self._seen <= cfg.recall_s) & np.isfinite(self._pos).all(axis=1)
        if cfg.recall_m <= 0 or len(self.rig) < 3 or not recent.any() or not len(pts):
            return out
        near = np.linalg.norm(self._pos[recent][:, None] - pts.X[None], axis=2) <= cfg.recall_m  # (R, P)
        # only one to one: hands together come back with both wrists by both points
        one = near & (near.sum(axis=1, keepdims=True) == 1) & (near.sum(axis=0, keepdims=True) == 1)
        rows, cols = np.nonzero(one)
        out[np.flatnonzero(recent)[rows]] = cols
        return out

    def _agrees(self, prev: tuple[float, np.ndarray] | None, named: np.ndarray) -> bool:
        """Whether an unclear identification's agreed names named (8, 3) m (NaN = left out) are
        where the frame before's best labelling prev (time, (8, 3) m) named them, within
        ``gate_m`` (always, with two cameras). Asked when a shoulder is named on a point that
        may be a ghost (fewer than three views, one missing it). Back from a blackout with the
        hands held together at shoulder height (a swordplay, seed 601 002_07), one frame's
        points lacked a shoulder (a 2-view point 14 cm off) and every close labelling agreed on
        a 2-view ghost by the hands and the left shoulder as the shoulders; named at once, the
        wrong names were tracked for 2.2 s. The frame before, the best labelling had named the
        shoulders right."""
        if len(self.rig) < 3:
            return True
        if prev is None or prev[0] < self._t_prev - 1e-6:
            return False
        on = np.isfinite(named).all(axis=1)
        d = np.linalg.norm(named[on] - prev[1][on], axis=1)
        return bool(np.isfinite(d).all() and (d <= self.config.gate_m).all())

    def _raised(self, pts: Points3D) -> Body:
        """The body for identifying afresh: its shoulders' ceiling raised by the height of the
        lowest sure point (>= 3 views) above an ankle standing on the floor, when there are
        more sure points than the legs' four and one of them is a shin above that point,
        upright (rise >= ``_UPRIGHT`` of its length): a subject standing up there. A subject
        standing on a structure when the labels were lost (a climbing frame after a blackout)
        has its shoulders above the ceiling of one standing on the floor, and the knees were
        named as shoulders. Not with the legs alone in view (the upper body above the
        cameras): the knees, a shoulder width apart, would be; nor for a climber hanging from a
        bar, knees pulled up, whose wrists overhead were named as shoulders. Only here: the
        audit, able to name shoulders up there, took a wrist passing at shoulder height for a
        shoulder."""
        sure = pts.X[pts.n_views >= 3]
        if len(sure) <= len(SIDES) * 2:  # a knee and an ankle per side
            return self._body
        body = self._body
        foot = sure[np.argmin(sure[:, 2])]
        rise = sure[:, 2] - foot[2]
        shin = np.abs(np.linalg.norm(sure - foot, axis=1) - body.shin) <= body.tol
        if not (shin & (rise >= _UPRIGHT * body.shin)).any():  # no knee above that foot: not standing
            return body
        lift = float(foot[2]) - ANKLE_HEIGHT
        return replace(body, top=body.top + lift) if lift > 0 else body

    def _steady_since(self, X: np.ndarray, t: float) -> float:
        """Since when (s) an unclear identification's best labelling, its markers X (8, 3) m
        (NaN = unnamed), has named the same markers within ``gate_m`` of where it named them the
        frame before: a runner-up close in score (the
        mirror image leaving a knee out, a subject back from a blackout) that never takes the
        lead is no reason to wait the whole ``max_wait``. Used with >= 3 cameras only: with two,
        every point is a 2-view point and a wrong labelling held as steady (a held-out
        backward-dribbling take went from 56 to 100 % of its confident frames > 20 cm off)."""
        since = t
        if self._steady is not None and self._steady[1] >= self._t_prev - 1e-6:
            t0, _t1, Y = self._steady
            same = np.isfinite(X).all(axis=1) == np.isfinite(Y).all(axis=1)
            near = np.linalg.norm(np.nan_to_num(X - Y), axis=1) <= self.config.gate_m
            if same.all() and near.all():
                since = t0
        self._steady = (since, t, X)
        return since

    def _update(self, out: np.ndarray, t: float, reset: bool = False, shared: np.ndarray | None = None,
                kept: np.ndarray | None = None) -> None:
        """Move the tracks to the named markers out (8, 3); shared (8,) bool: markers placed
        either side of a merged point, whose positions are partly a guess. reset: the names
        are new, the tracks restart (but those of kept (8,) bool, when given)."""
        named = np.isfinite(out).all(axis=1)
        fresh = self._legs_fresh(out, named, t, reset)
        if reset:
            self._reset_timers()
            self._t_identified = t
            restart = np.ones(N_MARKERS, bool) if kept is None else ~kept
            self._pos[restart] = np.nan
            self._seen[restart] = -np.inf
            self._vel[restart] = 0.0
            self._on_point[restart] = -np.inf
        self._on_point[named & ~self._rescued] = t
        for m in np.flatnonzero(named):
            dt = t - self._seen[m]
            if shared is not None and shared[m]:
                self._vel[m] *= 0.5
                self._pos[m], self._seen[m] = out[m], t
                continue
            if 0 < dt <= self.config.track_timeout and np.isfinite(self._pos[m]).all():
                v = (out[m] - self._pos[m]) / dt
                self._vel[m] = 0.5 * self._vel[m] + 0.5 * v
                speed = math.sqrt(float(self._vel[m] @ self._vel[m]))  # np.linalg.norm's sum, at a third of its cost
                if speed > 8.0:
                    self._vel[m] *= 8.0 / speed
            else:
                self._vel[m] = 0.0
            self._pos[m] = out[m]
            self._seen[m] = t
        if named[LS] and named[RS]:
            f = facing_of(out[LS], out[RS])
            if f is not None:
                self._facing, self._t_facing = f, t
        self._legs_unsure = (self._legs_unsure or fresh) and not self._legs_confirmed(out, t)


def _held_since(since: float | None, holds: bool, t: float) -> float | None:
    """When a condition that holds at time t (s) has held since: ``since`` if it already held,
    t if it starts now, None when it does not hold."""
    if not holds:
        return None
    return t if since is None else since


def _between(pts: Points3D, assign: np.ndarray) -> np.ndarray:
    """(8,) bool: markers named (assign (8,): point per marker, -1 = none) on a point seen only
    in merged blobs or that may hold two knees or two ankles (:func:`_two_in_one`): somewhere
    between two markers, no place to measure a shin from."""
    out = np.zeros(N_MARKERS, bool)
    for m in np.flatnonzero(assign >= 0):
        p = assign[m]
        out[m] = pts.n_merged[p] >= pts.n_views[p] or _two_in_one(pts, p, legs=True)
    return out


def _legs_apart(assign: np.ndarray) -> bool:
    """All four leg markers named, each on a point of its own (assign (8,): point per marker,
    -1 = none): what the shin rules need to tell a swap from a merged point."""
    legs = assign[[LK, RK, LA, RA]]
    return bool((legs >= 0).all()) and len(set(legs.tolist())) == 4


def _shin_errors(body: Body, out: np.ndarray) -> tuple[list[float], list[float]]:
    """How far (m) the two knee-ankle distances of out (8, 3) are from the shin, as named (left,
    right leg) and with the ankles' names swapped (left knee to right ankle, right knee to left)."""
    return ([body.shin_error(out[LK], out[LA]), body.shin_error(out[RK], out[RA])],
            [body.shin_error(out[LK], out[RA]), body.shin_error(out[RK], out[LA])])


def _swapped_pair(out: np.ndarray, right: np.ndarray) -> tuple[int, int]:
    """Which pair to swap when the legs' shins fit better the other way round: swapping the
    knees or the ankles makes the same two shins, so the knees' order along the subject's right
    (3,) chooses: knees named crossed are the wrong pair (thighs hardly cross), else the ankles."""
    return (LK, RK) if float((out[RK] - out[LK]) @ right) < 0 else (LA, RA)


def _name_points(assign: np.ndarray, arow: np.ndarray, row_pt: np.ndarray, markers, points) -> None:
    """Name each marker of ``markers`` on the point of ``points`` beside it: assign, arow (8,)
    in place (arow: the point's assignment row in row_pt)."""
    for m, p in zip(markers, points):
        assign[m] = p
        arow[m] = int(np.flatnonzero(row_pt == p)[0])


def _guess_split(pred: np.ndarray, m: int, n: int, half: float, right: np.ndarray | None) -> np.ndarray | None:
    """Half the separation (3,) m of markers m, n that share a point, guessed without the blob
    moments: along the subject's right (3,) for a left/right pair when it is known (m the left
    one), else along the difference of their predictions pred (8, 3); at most half m. None:
    no direction known."""
    off = 0.5 * (pred[m] - pred[n])
    norm = float(np.linalg.norm(off))
    if right is not None and (m, n) in _LR_PAIRS:
        size = min(norm, half) if np.isfinite(norm) and norm > 0.02 else half
        return -size * right
    if not np.isfinite(norm) or norm < 1e-9:
        return None
    return off * min(1.0, half / norm)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (degrees, 0-180) between the vectors a, b (3,)."""
    cos = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _borrowed(pts: Points3D, points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """(N,) bool: each of ``points`` (N,) point indices uses, in every view it is seen in, a
    (merged) blob one of ``others`` (M,) point indices uses too: it has no blob of its own.
    (A ghost built where two named markers' merged blobs cross.)"""
    mine = pts.blob[:, points]  # (C, N)
    shared = ((mine[:, :, None] == pts.blob[:, others][:, None, :]) & (mine >= 0)[:, :, None]).any(axis=2)
    return ((mine < 0) | shared).all(axis=0) & (mine >= 0).any(axis=0)


def _nearest(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """(N,) distance (m) from each point of X (N, 3) to the nearest of Y (M, 3); inf when M = 0."""
    if not len(Y):
        return np.full(len(X), np.inf)
    return np.min(np.linalg.norm(X[:, None] - Y[None], axis=2), axis=1)


#: shoulders and wrists: the markers :meth:`Labeller._rescue` looks for in the blobs, and those
#: :meth:`Labeller._recover` finds only as far off as they can have moved
_UPPER = (LS, RS, LW, RW)

#: per side: (its shoulder, its wrist, the other shoulder)
_ARMS = ((LS, LW, RS), (RS, RW, LS))

#: the knees and ankles
_LEG_MARKERS = np.array([LK, RK, LA, RA])


def marker_bits(named: np.ndarray) -> int | np.ndarray:
    """Bit set of markers (bit m = marker m, as ``marker_mask`` and :attr:`LabelQuality.renamed`)
    from named (8,) bool: an int; (F, 8): an (F,) int64 array."""
    bits = (np.asarray(named, np.int64) << np.arange(N_MARKERS)).sum(axis=-1)
    return int(bits) if np.ndim(bits) == 0 else bits


def bit_markers(bits: int | np.ndarray) -> np.ndarray:
    """The markers whose bit is set (inverse of :func:`marker_bits`): (8,) bool for an int,
    (F, 8) for an (F,) int array."""
    return (np.asarray(bits, np.int64)[..., None] >> np.arange(N_MARKERS)) & 1 == 1


#: a shin at least this steep (rise over length) stands on its foot
_UPRIGHT = 0.8
#: LabelQuality.renamed with every marker's bit set
_ALL = marker_bits(np.ones(N_MARKERS, bool))
#: identification leaves out the points made with a static reflection's blob (:meth:`Labeller._real`)
#: when this many others are left
_IDENTIFY_REAL = 4


def _permutations(swaps: tuple[tuple[tuple[int, int], ...], ...]) -> np.ndarray:
    """(S, 8) marker order of each swap of (m, n) name pairs: markers[perm] swaps them."""
    out = np.tile(np.arange(N_MARKERS), (len(swaps), 1))
    for row, pairs in zip(out, swaps):
        for m, n in pairs:
            row[[m, n]] = row[[n, m]]
    return out


#: the two knees and the two ankles, (left, right) each
_LEG_PAIRS = ((LK, RK), (LA, RA))

#: the confusions :meth:`Labeller.refit` and (but for both legs at once) :meth:`Labeller._swap_to_fit`
#: check, as (S, 8) marker orders: a wrist and its shoulder, the wrists, the knees, the ankles,
#: the legs, a knee and its ankle, a wrist and the other shoulder, the upper body's mirror image
#: (shoulders and wrists: the chest turned round from the legs, which no body does; held-out
#: subjects' databases, 49 clips at every check: the truth's upper mirror never fitted clearly
#: better, and was told from the truth in 17-100 % of a clip's checks), the mirror image; and
#: (S, 8) the markers each one moves
_FIT_SWAP_PAIRS = (
    ((LS, LW),), ((RS, RW),), ((LW, RW),), ((LK, RK),), ((LA, RA),), _LEG_PAIRS, ((LK, LA),),
    ((RK, RA),), ((LS, RW),), ((RS, LW),), ((LS, RS), (LW, RW)), ((LS, RS), (LW, RW), (LK, RK), (LA, RA)))
_FIT_SWAPS = _permutations(_FIT_SWAP_PAIRS)
_FIT_MOVES = _FIT_SWAPS != np.arange(N_MARKERS)
_MIRROR = len(_FIT_SWAPS) - 1  #: the row of _FIT_SWAPS naming every marker for its other side
_UPPER_MIRROR = _FIT_SWAP_PAIRS.index(((LS, RS), (LW, RW)))  #: the row naming the shoulders and wrists so
_LEGS = _FIT_SWAP_PAIRS.index(_LEG_PAIRS)  #: the row naming each leg for the other
_LR_PAIRS = {(LS, RS), (LW, RW), (LK, RK), (LA, RA)}
#: a knee and the other leg's ankle (:meth:`Labeller._part`)
_KNEE_OTHER_ANKLE = {(LK, RA), (RK, LA)}


def _disputed(labels: np.ndarray, rivals: list) -> np.ndarray:
    """(8,) bool: markers whose point (labels (8,), -1 = unnamed) some rival labelling names
    differently: it gives the marker another point, or gives the point to another marker
    instead. A rival that leaves a marker unnamed, or names its point for it and another
    marker too (a merged point), does not dispute it."""
    out = np.zeros(N_MARKERS, bool)
    for h in rivals:
        other = h.labels
        out |= (other >= 0) & (other != labels)
        for m in np.flatnonzero((labels >= 0) & (other != labels)):
            if any(other[n] == labels[m] and labels[n] != labels[m] for n in range(N_MARKERS)):
                out[m] = True
    return out


def _margin(labels: np.ndarray, score: float, rivals: list) -> float:
    """How much a labelling (8,) scoring ``score`` leads the best of the rival hypotheses that
    dispute one of its names (its score when none does)."""
    scores = [h.score for h in rivals if (_disputed(labels, [h]) & (labels >= 0)).any()]
    return score - max(scores) if scores else score


def _two_in_one(pts: Points3D, p: int, legs: bool = False) -> bool:
    """Point p may hold two markers: its blobs are double-sized everywhere, or merged in all
    its views but at most one, or for the two knees or the two ankles (legs) but at most two
    (two knees side by side, 15 cm apart, merged in two views of four and one hiding the other
    in the other two: the left knee was named on the point 9 cm off and the right one left
    out for 14 frames, 006_02 seed 3)."""
    return bool(pts.merged_all[p]) or (not pts.mirrored[p] and pts.n_merged[p] >= 2
                                       and pts.n_merged[p] >= pts.n_views[p] - (2 if legs else 1))


def facing_of(left: np.ndarray, right: np.ndarray) -> np.ndarray | None:
    """Horizontal unit facing of a body whose shoulders are at left, right (facing = up x right)."""
    r = right - left
    f = np.array([-r[1], r[0]])
    n = float(np.hypot(*f))
    return None if n < 1e-6 else f / n
