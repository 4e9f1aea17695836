"""Marker identities in one camera: T-pose labelling, then frame-to-frame tracking.

* **Labelling** from the standard pose (:func:`samba_mote.tpose_label.label_tpose`), seen
  from the front or the back: from the camera calibration when the mote has one, else from
  ``TrackConfig.tpose_view``. Re-checked every ``recheck_every`` frames.
* **Tracking** (:class:`MarkerTracker`): constant-velocity prediction (alpha-beta filter),
  gating, minimum-distance assignment (exact within small conflicting groups), merge
  detection (a blob that also holds another track's prediction, or is much larger than
  expected, is flagged MERGED for every track inside it and does not update their motion),
  coasting through short gaps (PREDICTED), then LOST with a growing re-acquisition gate.
  If most markers stay lost, the tracker re-labels from the next T-pose it sees. A merged
  pair is followed through the merge by splitting its blob along the long axis.
* **Certainty**: when a merge ends ambiguously (small assignment margin, never seen apart,
  one marker hidden by the other, an unknown marker in the blob) or a track comes back from a
  gap next to another, its identity is in doubt and it is published unlabelled with
  FLAG_UNCERTAIN instead of risking a swap. Identities come back with a T-pose or by
  elimination (all 8 seen as separate blobs, one in doubt).
* **Unlabelled mode**: every blob goes out with label 255 (wand calibration).

Units: pixels and pixels per second; time from the frame's ``t_ns``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from samba_common.skeleton import N_MARKERS
from samba_common.wire import FLAG_LOST, FLAG_MERGED, FLAG_PREDICTED, FLAG_TRACKED, FLAG_UNCERTAIN, UNLABELLED

from .assign import _min_cost_assignment
from .tpose_label import (L_AN, L_KN, L_SH, L_WR, R_AN, R_KN, R_SH, R_WR, TPOSE_TEMPLATE, label_tpose,
                          view_from_calibration)

log = logging.getLogger(__name__)

__all__ = ["MarkerTracker", "TrackConfig", "TrackOutput", "label_tpose", "view_from_calibration",
           "TPOSE_TEMPLATE", "L_SH", "R_SH", "L_WR", "R_WR", "L_KN", "R_KN", "L_AN", "R_AN"]


@dataclass(frozen=True)
class TrackConfig:
    """Tracking settings (``[track]`` in configs/mote.toml)."""

    mode: str = "labelled"  #: "labelled" or "unlabelled"
    tpose_view: str = "front"  #: without calibration: T-pose seen from the "front" or the "back"
    init_frames: int = 3  #: consecutive T-pose frames needed to (re)label
    init_tolerance: float = 0.06  #: max affine residual of the T-pose fit / template height
    init_max_blobs: int = 11  #: give up labelling a frame with more blobs than this
    gate_px: float = 5.0  #: base association gate (px)
    gate_speed: float = 0.5  #: + this x predicted displacement this frame
    gate_growth: float = 0.5  #: + this many px per frame a track has been missing
    gate_max: float = 8.0  #: cap of the gate (px); small, so a lost track never jumps to another limb
    alpha: float = 1.0  #: position gain (1 = trust the measurement)
    beta: float = 0.5  #: velocity gain
    coast_frames: int = 8  #: frames a missing track is PREDICTED before it becomes LOST
    coast_decay: float = 0.85  #: velocity decay per frame while coasting
    stale_penalty: float = 0.3  #: assignment cost (px) per frame since a track's last clean measurement
    split_min_px: float = 1.5  #: a merged pair is split along its long axis when this far apart (px)
    recheck_every: int = 15  #: look for a T-pose every this many frames (exactly 8 blobs) and re-label if it disagrees
    split_margin: float = 1.0  #: px; a split decided by less than this makes both labels uncertain
    doubt_after_gap: int = 2  #: a track back after more missing frames than this, near another, is uncertain
    merge_margin: float = 1.0  #: px added to a blob's radius when testing predictions inside it
    merge_area_ratio: float = 1.35  #: blob area / expected area that means two markers
    reinit_lost: int = 5  #: re-label from a T-pose when at least this many markers are lost
    default_fps: float = 60.0  #: used for dt when timestamps do not advance

    def __post_init__(self) -> None:
        if self.mode not in ("labelled", "unlabelled"):
            raise ValueError(f"track mode must be 'labelled' or 'unlabelled', got {self.mode!r}")
        if self.tpose_view not in ("front", "back"):
            raise ValueError(f"tpose_view must be 'front' or 'back', got {self.tpose_view!r}")


def _major_axis(vu: float, cuv: float, vv: float) -> tuple[float, float, float]:
    """Second moments (var_u, cov_uv, var_v) px^2 -> (d, eu, ev): d = 2 sqrt(l1 - l0) px (the
    eigenvalue gap of the 2x2 covariance) and (eu, ev) the unit major axis (closed form: a
    LAPACK call costs ~20 us on a mote)."""
    gap = math.sqrt((vu - vv) ** 2 + 4.0 * cuv * cuv)
    theta = 0.5 * math.atan2(2.0 * cuv, vu - vv)
    return 2.0 * math.sqrt(gap), math.cos(theta), math.sin(theta)


@dataclass
class TrackOutput:
    """Records for one packet: labels (N,) uint8, uv (N, 2) float32, area (N,) uint16, flags (N,)
    uint8; blob (N,) int64 the detection each record measured (-1: a prediction)."""

    labels: np.ndarray
    uv: np.ndarray
    area: np.ndarray
    flags: np.ndarray
    blob: np.ndarray

    def moments(self, cov: np.ndarray | None) -> np.ndarray:
        """(N, 3) float32 second moments of each record's blob from the detections' cov (B, 3)
        px^2; NaN for predictions (or without cov)."""
        out = np.full((len(self.blob), 3), np.nan, np.float32)
        if cov is not None and len(cov):
            has = self.blob >= 0
            out[has] = cov[self.blob[has]]
        return out


class MarkerTracker:
    """Keeps the identities of the 8 markers across frames. Not thread-safe."""

    def __init__(self, config: TrackConfig | None = None, view: str | None = None) -> None:
        self.cfg = config or TrackConfig()
        self.view = view or self.cfg.tpose_view
        self.initialised = False
        # per-track state as plain Python lists (8 tracks: cheaper than numpy calls per frame);
        # the pos/vel/area/missing/stale properties give numpy copies
        self._pos: list[list[float]] = [[math.nan, math.nan] for _ in range(N_MARKERS)]
        self._vel: list[list[float]] = [[0.0, 0.0] for _ in range(N_MARKERS)]
        self._area: list[float] = [0.0] * N_MARKERS
        self._missing: list[int] = [0] * N_MARKERS
        self._stale: list[int] = [0] * N_MARKERS  # frames since a clean (unmerged) measurement
        self.certain = np.ones(N_MARKERS, bool)  # identity sure (else published unlabelled)
        self.partners: list[set[int]] = [set() for _ in range(N_MARKERS)]  # merged with, this episode
        self.uncertain_events = 0
        self.unresolved = np.zeros(N_MARKERS, bool)  # merged with no visible separation this episode
        self._last_t: int | None = None
        self._frame = 0
        self._init_streak = 0
        self._init_prev: np.ndarray | None = None
        self.swaps_suspected = 0
        self.reinits = 0

    @property
    def pos(self) -> np.ndarray:
        """(8, 2) float px: each track's position (NaN before labelling); a copy."""
        return np.array(self._pos, np.float64).reshape(N_MARKERS, 2)

    @pos.setter
    def pos(self, value: np.ndarray) -> None:
        self._pos = np.asarray(value, np.float64).reshape(N_MARKERS, 2).tolist()

    @property
    def vel(self) -> np.ndarray:
        """(8, 2) float px/s: each track's velocity; a copy."""
        return np.array(self._vel, np.float64).reshape(N_MARKERS, 2)

    @vel.setter
    def vel(self, value: np.ndarray) -> None:
        self._vel = np.asarray(value, np.float64).reshape(N_MARKERS, 2).tolist()

    @property
    def area(self) -> np.ndarray:
        """(8,) float px: each track's learnt single-marker blob area (0 = unknown); a copy."""
        return np.array(self._area, np.float64)

    @area.setter
    def area(self, value: np.ndarray) -> None:
        self._area = np.asarray(value, np.float64).reshape(N_MARKERS).tolist()

    @property
    def missing(self) -> np.ndarray:
        """(8,) int64: frames each track has gone unmeasured; a copy."""
        return np.array(self._missing, np.int64)

    @missing.setter
    def missing(self, value: np.ndarray) -> None:
        self._missing = np.asarray(value, np.int64).reshape(N_MARKERS).tolist()

    @property
    def stale(self) -> np.ndarray:
        """(8,) int64: frames since each track's last clean (unmerged) measurement; a copy."""
        return np.array(self._stale, np.int64)

    @stale.setter
    def stale(self, value: np.ndarray) -> None:
        self._stale = np.asarray(value, np.int64).reshape(N_MARKERS).tolist()

    def reset(self) -> None:
        """Forget all identities (the next T-pose labels again)."""
        self.__init__(self.cfg, self.view)

    # -------------------------------------------------------------------------------- labelling
    def _try_init(self, uv: np.ndarray, area: np.ndarray, relabel_only: bool = False) -> bool:
        """Look for a T-pose; (re)label after ``init_frames`` consistent sightings. With
        relabel_only, a T-pose that agrees with the current labels changes nothing."""
        found = label_tpose(uv, self.view, self.cfg.init_tolerance, self.cfg.init_max_blobs)
        if found is None:
            self._init_streak, self._init_prev = 0, None
            return False
        pts = uv[found[0]].astype(float)
        if relabel_only and np.all(np.linalg.norm(pts - self.pos, axis=1) < 2.0):
            self._init_streak, self._init_prev = 0, None
            return False
        if self._init_prev is not None and np.abs(pts - self._init_prev).max() > 3.0:
            self._init_streak = 0
        self._init_prev = pts
        self._init_streak += 1
        if self._init_streak < self.cfg.init_frames:
            return False
        self.pos = pts
        self.vel = np.zeros((N_MARKERS, 2))
        self.area = area[found[0]].astype(float)
        self.missing = np.zeros(N_MARKERS, np.int64)
        self.stale = np.zeros(N_MARKERS, np.int64)
        self.certain[:] = True
        self.partners = [set() for _ in range(N_MARKERS)]
        self.unresolved[:] = False
        self.initialised = True
        self._init_streak, self._init_prev = 0, None
        log.info("labelled the 8 markers from a T-pose (%s view, residual %.3f)", self.view, found[1])
        return True

    # -------------------------------------------------------------------------------- tracking
    def update(self, t_ns: int, uv: np.ndarray, area: np.ndarray, cov: np.ndarray | None = None) -> TrackOutput:
        """One frame: blobs uv (N, 2) px, area (N,) px and optional second moments cov (N, 3)
        (var_u, cov_uv, var_v, px^2, used to split merged pairs) -> packet records.

        Per-track work runs on plain Python floats (8 tracks: cheaper than numpy calls); only
        the (8, N) distance matrix is computed with numpy."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        area = np.asarray(area, np.float64).reshape(-1)
        n = len(uv)
        cfg = self.cfg
        dt = 1.0 / cfg.default_fps
        if self._last_t is not None and t_ns > self._last_t:
            dt = min((t_ns - self._last_t) * 1e-9, 0.5)
        self._last_t = t_ns
        self._frame += 1
        if cfg.mode == "unlabelled":
            return self._unlabelled(uv, area)
        coast = cfg.coast_frames
        MI = self._missing
        n_lost = sum(1 for x in MI if x > coast)
        recheck = (self.initialised and cfg.recheck_every > 0 and self._frame % cfg.recheck_every == 0
                   and n == N_MARKERS)
        if not self.initialised or n_lost >= cfg.reinit_lost or recheck:
            was = self.initialised
            if self._try_init(uv, area, relabel_only=recheck and n_lost < cfg.reinit_lost):
                if was:
                    self.reinits += 1
                return self._output(uv, area, {m: int(b) for m, b in enumerate(self._init_index(uv))}, set(), n)
            if not self.initialised:
                return self._unlabelled(uv, area)
        # the state lists are updated in place at the end (their items are replaced, never mutated)
        P, V, A, ST = self._pos, self._vel, self._area, self._stale
        gate_px, gate_speed, gate_growth, gate_max = cfg.gate_px, cfg.gate_speed, cfg.gate_growth, cfg.gate_max
        PR: list[list[float]] = []
        gl: list[float] = []
        fin: list[bool] = []
        for m in range(N_MARKERS):
            mu, mv = V[m][0] * dt, V[m][1] * dt
            pu, pv = P[m][0] + mu, P[m][1] + mv
            PR.append([pu, pv])
            gl.append(min(gate_px + gate_speed * math.hypot(mu, mv) + gate_growth * ST[m], gate_max))
            fin.append(math.isfinite(pu) and math.isfinite(pv))
        active = [x <= coast for x in MI]  # merged tracks stay active
        all_active, all_finite = all(active), all(fin)
        pred = np.array(PR)
        assigned: dict[int, int] = {}
        if n:
            D = np.hypot(pred[:, 0:1] - uv[:, 0], pred[:, 1:2] - uv[:, 1])
            if not all_finite:
                D[~np.array(fin)] = np.inf
            # stage 1: active tracks; ties (two tracks at one place) go to the track measured
            # cleanly most recently
            Da = D if all_active else np.where(np.array(active)[:, None], D, np.inf)
            assigned.update(_min_cost_assignment(Da, gl, penalty=ST, penalty_scale=cfg.stale_penalty))
        Dl: list[list[float]] = []  # D as lists, when needed
        # merge detection: an unassigned active track whose prediction lies inside an assigned
        # blob, or near one that is larger than one marker, shares that blob
        arl = area.tolist()
        blob_r: list[float] = []  # blob radius (px), computed when needed
        merged: set[int] = set()
        if n and len(assigned) < N_MARKERS:
            Dl = D.tolist()
            blob_r = [math.sqrt(max(a, 1.0) / math.pi) for a in arl]
            owner = {b: m for m, b in assigned.items()}
            margin, ratio = cfg.merge_margin, cfg.merge_area_ratio
            for m in range(N_MARKERS):
                if m in assigned or not active[m] or not fin[m]:
                    continue
                Dm = Dl[m]
                for b in sorted(range(n), key=Dm.__getitem__)[:3]:
                    if b not in owner or Dm[b] >= gl[m]:
                        continue
                    other = owner[b]
                    expected = max(min(A[m], A[other]), 1.0)
                    inside = Dm[b] <= blob_r[b] + margin
                    big = arl[b] >= ratio * expected and Dm[b] <= blob_r[b] + margin + 1.0
                    if inside or big:
                        assigned[m] = b
                        merged |= {m, other}
                        break
        # a blob much larger than its track's single-marker area holds another marker we do not
        # track right now (lost or never seen): its centroid is biased and its split unsure
        ratio = cfg.merge_area_ratio
        for m, b in list(assigned.items()):
            if A[m] > 0 and arl[b] >= ratio * A[m] + 2.0 and m not in merged:
                merged.add(m)
                self.partners[m].add(-1)
                self.unresolved[m] = True
        # stage 2: lost tracks re-acquire blobs nobody claimed, nearest first
        if n and not all_active:
            if not Dl:
                Dl = D.tolist()
            taken = set(assigned.values())
            cands = sorted((Dl[m][b], m, b) for m in range(N_MARKERS) if not active[m] for b in range(n)
                           if b not in taken and Dl[m][b] < gl[m])
            for _d, m, b in cands:
                if m not in assigned and b not in taken:
                    assigned[m] = b
                    taken.add(b)
                    self._doubt(m)
        # a merged pair: split the blob along its long axis (second moments), keeping the
        # pair's predicted relative offset to tell which end is which
        sub: dict[int, list[float]] = {}
        groups: dict[int, list[int]] = {}
        for m in merged:
            groups.setdefault(assigned[m], []).append(m)
        uvl = uv.tolist()
        if groups and not blob_r:
            blob_r = [math.sqrt(max(a, 1.0) / math.pi) for a in arl]
        for b, ms in groups.items():
            bu, bv = uvl[b]
            if len(ms) == 2 and cov is not None:
                a_, c_ = sorted(ms)
                ru, rv = PR[a_][0] - PR[c_][0], PR[a_][1] - PR[c_][1]
                if not (math.isfinite(ru) and math.isfinite(rv)):
                    ru, rv = 0.0, 0.0
                vu, cuv, vv = (float(x) for x in cov[b].tolist())
                d, eu, ev = _major_axis(vu, cuv, vv)
                single = max(min(A[a_], A[c_]), 1.0)
                if d < cfg.split_min_px or arl[b] < cfg.merge_area_ratio * single:
                    # no visible second marker: merged head-on, or one hides the other
                    self.unresolved[a_] = self.unresolved[c_] = True
                if d >= cfg.split_min_px:
                    su, sv = d * eu, d * ev
                    dot = su * ru + sv * rv
                    if dot == 0.0:  # no preferred end: keep LAPACK's sign (as eigh gives it)
                        evec = np.linalg.eigh(np.array([[vu, cuv], [cuv, vv]]))[1]
                        su, sv = d * float(evec[0, 1]), d * float(evec[1, 1])
                    elif dot < 0:
                        su, sv = -su, -sv
                else:
                    norm = math.hypot(ru, rv)
                    if norm < 2 * blob_r[b]:
                        su, sv = ru, rv
                    else:
                        s = 2 * blob_r[b] / norm
                        su, sv = ru * s, rv * s
                sub[a_] = [bu + su / 2, bv + sv / 2]
                sub[c_] = [bu - su / 2, bv - sv / 2]
            else:
                for m in ms:
                    self.unresolved[m] = True
                r = blob_r[b]
                for m in ms:  # three or more: coast, but stay inside the blob
                    ou, ov = PR[m][0] - bu, PR[m][1] - bv
                    norm = math.hypot(ou, ov)
                    if norm > r:
                        ou, ov = ou * (r / norm), ov * (r / norm)
                    sub[m] = [bu + ou, bv + ov]
        self._update_certainty(pred, uv, assigned, merged, groups, gl, MI, fin)
        # state update (plain Python floats: cheaper than numpy calls for 8 tracks)
        alpha, beta, decay = cfg.alpha, cfg.beta, cfg.coast_decay
        for m in range(N_MARKERS):
            b = assigned.get(m)
            if b is not None:
                z = sub[m] if m in sub else uvl[b]
                if MI[m] > 0 or not fin[m]:
                    P[m], V[m] = [z[0], z[1]], [0.0, 0.0]
                else:
                    g = 0.5 * beta if m in merged else beta
                    iu, iv = z[0] - PR[m][0], z[1] - PR[m][1]
                    P[m] = [PR[m][0] + alpha * iu, PR[m][1] + alpha * iv]
                    V[m] = [V[m][0] + g * iu / dt, V[m][1] + g * iv / dt]
                MI[m] = 0
                if m in merged:
                    ST[m] += 1
                else:
                    ST[m] = 0
                    ab = arl[b]
                    if A[m] <= 0:
                        A[m] = ab
                    else:  # learn the single-marker area; adapt only slowly to larger blobs
                        A[m] += (0.2 if ab < 1.3 * A[m] else 0.01) * (ab - A[m])
            else:
                MI[m] += 1
                ST[m] += 1
                if MI[m] <= coast and fin[m]:
                    P[m], V[m] = PR[m], [V[m][0] * decay, V[m][1] * decay]
                else:
                    V[m] = [0.0, 0.0]
        return self._output(uv, area, assigned, merged, n, (uvl, arl, P, MI))

    def _doubt(self, m: int) -> None:
        if self.certain[m]:
            self.certain[m] = False
            self.uncertain_events += 1

    def _update_certainty(self, pred: np.ndarray, uv: np.ndarray, assigned: dict[int, int], merged: set[int],
                          groups: dict[int, list[int]], gate: list[float], missing: list[int],
                          finite: list[bool]) -> None:
        """Identity bookkeeping: a pair leaving a merge keeps its labels only if the split was
        unambiguous; a track back from a gap keeps its label only if no other track could
        claim its blob; the last uncertain track of eight becomes certain by elimination.
        pred (8, 2) px; gate, missing, finite: per track, before this frame's update."""
        cfg = self.cfg
        for ms in groups.values():
            for m in ms:
                self.partners[m] |= set(ms) - {m}
        clean = {m: b for m, b in assigned.items() if m not in merged}
        for m, b in clean.items():
            if self.partners[m]:
                doubt = bool(self.unresolved[m])
                for k in list(self.partners[m]):
                    if k < 0:  # an unknown marker shared the blob
                        doubt = True
                    elif k in clean and finite[m] and finite[k]:
                        zm, zk = uv[b], uv[clean[k]]
                        same = np.sum((pred[m] - zm) ** 2) + np.sum((pred[k] - zk) ** 2)
                        swap = np.sum((pred[m] - zk) ** 2) + np.sum((pred[k] - zm) ** 2)
                        margin = (swap - same) / (2.0 * max(float(np.linalg.norm(zm - zk)), 1e-3))
                        if margin < cfg.split_margin or self.unresolved[k]:
                            doubt = True
                            self._doubt(k)
                        self.partners[k].discard(m)
                        if not self.partners[k]:
                            self.unresolved[k] = False
                    elif k not in assigned:  # the partner vanished when they separated
                        doubt = True
                        self.partners[k].discard(m)
                    else:  # partner still merged with another: this one's side is unknown
                        doubt = True
                if doubt:
                    self._doubt(m)
                self.partners[m] = set()
                self.unresolved[m] = False
            elif missing[m] > cfg.doubt_after_gap and finite[m]:
                others = [k for k in range(N_MARKERS) if k != m and finite[k]
                          and np.linalg.norm(pred[k] - uv[b]) < gate[k] + gate[m]]
                if others:
                    self._doubt(m)
        # elimination: all eight measured as separate blobs and only one of them uncertain
        if len(clean) == N_MARKERS:
            unsure = [m for m, c in enumerate(self.certain.tolist()) if not c]
            if len(unsure) == 1 and len(set(clean.values())) == N_MARKERS:
                self.certain[unsure[0]] = True

    def _init_index(self, uv: np.ndarray) -> np.ndarray:
        D = np.linalg.norm(self.pos[:, None, :] - uv[None, :, :], axis=2)
        return D.argmin(1)

    def _output(self, uv: np.ndarray, area: np.ndarray, assigned: dict[int, int], merged: set[int], n: int,
                lists: tuple[list, list, list, list] | None = None) -> TrackOutput:
        """Packet records: one per marker (measured, predicted or lost; uncertain ones unlabelled),
        then every blob no track claimed (unlabelled). lists: (uv, area, pos, missing) already
        as Python lists (saves converting them again)."""
        labels, pts, areas, flags, blobs = [], [], [], [], []
        if lists is None:
            uvl, arl, posl, miss = uv.tolist(), area.tolist(), self._pos, self._missing
        else:
            uvl, arl, posl, miss = lists
        cert = self.certain.tolist()
        coast = self.cfg.coast_frames
        used = set(assigned.values())
        emitted: set[int] = set()
        for m in range(N_MARKERS):
            b = assigned.get(m)
            if b is not None:
                mflag = FLAG_MERGED if m in merged else 0
                if not cert[m]:
                    if b in emitted:
                        continue
                    labels.append(UNLABELLED)
                    flags.append(FLAG_UNCERTAIN | mflag)
                else:
                    labels.append(m)
                    flags.append(FLAG_TRACKED | mflag)
                emitted.add(b)
                pts.append(uvl[b])
                areas.append(arl[b])
                blobs.append(b)
            else:
                labels.append(m)
                pts.append(posl[m])
                areas.append(0)
                flags.append(FLAG_PREDICTED if miss[m] <= coast else FLAG_LOST)
                blobs.append(-1)
        if len(used) < n:
            for b in range(n):
                if b not in used:
                    labels.append(UNLABELLED)
                    pts.append(uvl[b])
                    areas.append(arl[b])
                    flags.append(0)
                    blobs.append(b)
        if arl and (min(arl) < 0 or max(arl) > 65535):
            areas = [min(max(a, 0), 65535) for a in areas]
        return TrackOutput(np.array(labels, np.uint8), np.array(pts, np.float32).reshape(-1, 2),
                           np.array(areas).astype(np.uint16), np.array(flags, np.uint8), np.array(blobs, np.int64))

    @staticmethod
    def _unlabelled(uv: np.ndarray, area: np.ndarray) -> TrackOutput:
        n = len(uv)
        return TrackOutput(np.full(n, UNLABELLED, np.uint8), uv.astype(np.float32),
                           np.clip(area, 0, 65535).astype(np.uint16), np.zeros(n, np.uint8), np.arange(n))
