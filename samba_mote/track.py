"""Marker identities in one camera: T-pose labelling, then frame-to-frame tracking.

* **Labelling** (:func:`label_tpose`): the 8 markers of a T-pose lie almost in one plane (the
  body's frontal plane), so their image is an affine image of a planar template. Blobs are
  grouped by height (4 upper = shoulders + wrists, then knees, then ankles), the outer upper
  pair are wrists, and left/right follows from the view: seen from the front the subject's
  right is on the image left. With more than 8 blobs (clutter), every 8-subset is tried and
  the one with the smallest normalised affine residual wins. Front/back comes from the
  camera calibration when the mote has one, else from ``TrackConfig.tpose_view``.
* **Tracking** (:class:`MarkerTracker`): constant-velocity prediction (alpha-beta filter),
  gating, minimum-distance assignment (exact within small conflicting groups), merge
  detection (a blob that also holds another track's prediction, or is much larger than
  expected, is flagged MERGED for every track inside it and does not update their motion),
  coasting through short gaps (PREDICTED), then LOST with a growing re-acquisition gate.
  If most markers stay lost, the tracker re-labels from the next T-pose it sees.
* **Unlabelled mode**: every blob goes out with label 255 (wand calibration).

Units: pixels and pixels per second; time from the frame's ``t_ns``.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import numpy as np

from samba_common.skeleton import N_MARKERS
from samba_common.wire import FLAG_LOST, FLAG_MERGED, FLAG_PREDICTED, FLAG_TRACKED, FLAG_UNCERTAIN, UNLABELLED

log = logging.getLogger(__name__)

# marker indices (MARKER_NAMES order)
L_SH, R_SH, L_WR, R_WR, L_KN, R_KN, L_AN, R_AN = range(8)

#: planar T-pose template, (8, 2): x toward the subject's right (m), z up (m)
TPOSE_TEMPLATE = np.array([
    [-0.18, 1.45], [0.18, 1.45],  # shoulders
    [-0.72, 1.45], [0.72, 1.45],  # wrists
    [-0.16, 0.50], [0.16, 0.50],  # knees (feet apart, see samba_mote.sim.tpose)
    [-0.22, 0.08], [0.22, 0.08],  # ankles
])


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
    recover_frames: int = 6  #: frames one plausible labelling of uncertain markers must hold
    merge_margin: float = 1.0  #: px added to a blob's radius when testing predictions inside it
    merge_area_ratio: float = 1.35  #: blob area / expected area that means two markers
    reinit_lost: int = 5  #: re-label from a T-pose when at least this many markers are lost
    default_fps: float = 60.0  #: used for dt when timestamps do not advance

    def __post_init__(self) -> None:
        if self.mode not in ("labelled", "unlabelled"):
            raise ValueError(f"track mode must be 'labelled' or 'unlabelled', got {self.mode!r}")
        if self.tpose_view not in ("front", "back"):
            raise ValueError(f"tpose_view must be 'front' or 'back', got {self.tpose_view!r}")


@dataclass
class TrackOutput:
    """Records for one packet: labels (N,) uint8, uv (N, 2) float32, area (N,) uint16, flags (N,) uint8."""

    labels: np.ndarray
    uv: np.ndarray
    area: np.ndarray
    flags: np.ndarray


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


def _min_cost_assignment(D: np.ndarray, gate: np.ndarray, C: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Pairs (track, blob) minimising the total cost C (T, N) (default D) among gated pairs
    D (T, N) < gate (T,).

    Tracks and blobs split into connected groups of gated pairs; groups up to 5 tracks are
    solved exactly (all injective matchings maximising the number of pairs, then the sum of
    distances); bigger groups greedily by distance.
    """
    ok = D < gate[:, None]
    if C is not None:
        D = C
    pairs: list[tuple[int, int]] = []
    T, N = D.shape
    # fast path: a track with a single gated blob that no other track can reach
    row = ok.sum(axis=1)
    col = ok.sum(axis=0)
    single = ok & (row[:, None] == 1) & (col[None, :] == 1)
    ts, bs = np.nonzero(single)
    pairs += list(zip(ts.tolist(), bs.tolist()))
    seen_t = single.any(axis=1) | (row == 0)
    if seen_t.all():
        return pairs
    for t0 in range(T):
        if seen_t[t0]:
            continue
        # grow the connected component
        ts, bs = {t0}, set()
        frontier_t = [t0]
        while frontier_t:
            new_b = set()
            for t in frontier_t:
                new_b |= set(np.flatnonzero(ok[t]).tolist())
            new_b -= bs
            bs |= new_b
            new_t = set()
            for b in new_b:
                new_t |= set(np.flatnonzero(ok[:, b]).tolist())
            new_t -= ts
            ts |= new_t
            frontier_t = list(new_t)
        for t in ts:
            seen_t[t] = True
        tl, bl = sorted(ts), sorted(bs)
        if len(tl) == 1 and len(bl) == 1:
            pairs.append((tl[0], bl[0]))
            continue
        if len(tl) <= 5 and len(bl) <= 7:
            best_key, best = None, []
            options = [[b for b in bl if ok[t, b]] + [None] for t in tl]
            for combo in itertools.product(*options):
                used = [b for b in combo if b is not None]
                if len(used) != len(set(used)):
                    continue
                cost = sum(D[t, b] ** 2 for t, b in zip(tl, combo) if b is not None)
                key = (-len(used), cost)
                if best_key is None or key < best_key:
                    best_key, best = key, [(t, b) for t, b in zip(tl, combo) if b is not None]
            pairs += best
        else:
            sub = [(D[t, b], t, b) for t in tl for b in bl if ok[t, b]]
            used_t, used_b = set(), set()
            for _, t, b in sorted(sub):
                if t not in used_t and b not in used_b:
                    pairs.append((t, b))
                    used_t.add(t)
                    used_b.add(b)
    return pairs


class MarkerTracker:
    """Keeps the identities of the 8 markers across frames. Not thread-safe."""

    def __init__(self, config: TrackConfig | None = None, view: str | None = None) -> None:
        self.cfg = config or TrackConfig()
        self.view = view or self.cfg.tpose_view
        self.initialised = False
        self.pos = np.full((N_MARKERS, 2), np.nan)
        self.vel = np.zeros((N_MARKERS, 2))
        self.area = np.zeros(N_MARKERS)
        self.missing = np.zeros(N_MARKERS, np.int64)
        self.stale = np.zeros(N_MARKERS, np.int64)  # frames since a clean (unmerged) measurement
        self.certain = np.ones(N_MARKERS, bool)  # identity sure (else published unlabelled)
        self.partners: list[set[int]] = [set() for _ in range(N_MARKERS)]  # merged with, this episode
        self.uncertain_events = 0
        self.unresolved = np.zeros(N_MARKERS, bool)  # merged with no visible separation this episode
        self.body_h = 0.0  # shoulder-to-ankle height (px) at labelling time
        self.reach_px = 0.0  # shoulder-to-wrist reach (px)
        self.shin_px = 0.0  # knee-to-ankle length (px)
        self._recover_key: tuple | None = None
        self._recover_streak = 0
        self.recovered = 0
        self._last_t: int | None = None
        self._frame = 0
        self._init_streak = 0
        self._init_prev: np.ndarray | None = None
        self.swaps_suspected = 0
        self.reinits = 0

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
        self.pos = pts.copy()
        self.vel[:] = 0.0
        self.area = area[found[0]].astype(float)
        self.missing[:] = 0
        self.stale[:] = 0
        self.certain[:] = True
        self.partners = [set() for _ in range(N_MARKERS)]
        self.unresolved[:] = False
        self.body_h = float(pts[[L_AN, R_AN], 1].mean() - pts[[L_SH, R_SH], 1].mean())
        arms = np.linalg.norm(pts[[L_WR, R_WR]] - pts[[L_SH, R_SH]], axis=1).max()
        self.reach_px = max(float(arms), 0.40 * self.body_h)
        self.shin_px = max(float(np.linalg.norm(pts[[L_KN, R_KN]] - pts[[L_AN, R_AN]], axis=1).max()), 0.3 * self.body_h)
        self._recover_key, self._recover_streak = None, 0
        self.initialised = True
        self._init_streak, self._init_prev = 0, None
        log.info("labelled the 8 markers from a T-pose (%s view, residual %.3f)", self.view, found[1])
        return True

    # -------------------------------------------------------------------------------- tracking
    def update(self, t_ns: int, uv: np.ndarray, area: np.ndarray, cov: np.ndarray | None = None) -> TrackOutput:
        """One frame: blobs uv (N, 2) px, area (N,) px and optional second moments cov (N, 3)
        (var_u, cov_uv, var_v, px^2, used to split merged pairs) -> packet records."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        area = np.asarray(area, np.float64).reshape(-1)
        n = len(uv)
        dt = 1.0 / self.cfg.default_fps
        if self._last_t is not None and t_ns > self._last_t:
            dt = min((t_ns - self._last_t) * 1e-9, 0.5)
        self._last_t = t_ns
        self._frame += 1
        if self.cfg.mode == "unlabelled":
            return self._unlabelled(uv, area)
        cfg = self.cfg
        n_lost = int((self.missing > cfg.coast_frames).sum())
        recheck = (self.initialised and cfg.recheck_every > 0 and self._frame % cfg.recheck_every == 0
                   and len(uv) == N_MARKERS)
        if not self.initialised or n_lost >= cfg.reinit_lost or recheck:
            was = self.initialised
            if self._try_init(uv, area, relabel_only=recheck and n_lost < cfg.reinit_lost):
                if was:
                    self.reinits += 1
                return self._output(uv, area, {m: int(b) for m, b in enumerate(self._init_index(uv))}, set(), n)
            if not self.initialised:
                return self._unlabelled(uv, area)
        move = self.vel * dt
        pred = self.pos + move
        step = np.hypot(move[:, 0], move[:, 1])
        active = self.missing <= cfg.coast_frames  # merged tracks stay active
        gate = np.minimum(cfg.gate_px + cfg.gate_speed * step + cfg.gate_growth * self.stale, cfg.gate_max)
        finite = np.isfinite(pred).all(axis=1)
        assigned: dict[int, int] = {}
        if n:
            D = np.hypot(pred[:, 0:1] - uv[:, 0], pred[:, 1:2] - uv[:, 1])
            if not finite.all():
                D[~finite] = np.inf
            # stage 1: active tracks; ties (two tracks at one place) go to the track measured
            # cleanly most recently
            Da = D if active.all() else np.where(active[:, None], D, np.inf)
            cost = Da + cfg.stale_penalty * self.stale[:, None] if self.stale.any() else None
            assigned.update(_min_cost_assignment(Da, gate, cost))
        else:
            D = np.zeros((N_MARKERS, 0))
        # merge detection: an unassigned active track whose prediction lies inside an assigned
        # blob, or near one that is larger than one marker, shares that blob
        blob_r = np.sqrt(np.maximum(area, 1.0) / np.pi)
        owner = {b: m for m, b in assigned.items()}
        merged: set[int] = set()
        for m in range(N_MARKERS):
            if m in assigned or not n or not active[m] or not finite[m]:
                continue
            for b in np.argsort(D[m])[:3]:
                b = int(b)
                if b not in owner or D[m, b] >= gate[m]:
                    continue
                other = owner[b]
                expected = max(min(self.area[m], self.area[other]), 1.0)
                inside = D[m, b] <= blob_r[b] + cfg.merge_margin
                big = area[b] >= cfg.merge_area_ratio * expected and D[m, b] <= blob_r[b] + cfg.merge_margin + 1.0
                if inside or big:
                    assigned[m] = b
                    merged |= {m, other}
                    break
        # a blob much larger than its track's single-marker area holds another marker we do not
        # track right now (lost or never seen): its centroid is biased and its split unsure
        if assigned:
            ms = np.fromiter(assigned.keys(), int, len(assigned))
            bs = np.fromiter(assigned.values(), int, len(assigned))
            big = (self.area[ms] > 0) & (area[bs] >= cfg.merge_area_ratio * self.area[ms] + 2.0)
            for m in ms[big].tolist():
                if m not in merged:
                    merged.add(m)
                    self.partners[m].add(-1)
                    self.unresolved[m] = True
        # stage 2: lost tracks re-acquire blobs nobody claimed, nearest first
        if n and not active.all():
            taken = set(assigned.values())
            cands = sorted((D[m, b], int(m), b) for m in np.flatnonzero(~active) for b in range(n)
                           if b not in taken and D[m, b] < gate[m])
            for _d, m, b in cands:
                if m not in assigned and b not in taken:
                    assigned[m] = b
                    taken.add(b)
                    self._doubt(m)
        # a merged pair: split the blob along its long axis (second moments), keeping the
        # pair's predicted relative offset to tell which end is which
        sub: dict[int, np.ndarray] = {}
        groups: dict[int, list[int]] = {}
        for m in merged:
            groups.setdefault(assigned[m], []).append(m)
        for b, ms in groups.items():
            if len(ms) == 2 and cov is not None:
                a_, c_ = sorted(ms)
                rel = pred[a_] - pred[c_]
                if not np.isfinite(rel).all():
                    rel = np.zeros(2)
                vu, cuv, vv = (float(x) for x in cov[b])
                ev, evec = np.linalg.eigh(np.array([[vu, cuv], [cuv, vv]]))
                d = 2.0 * np.sqrt(max(ev[1] - ev[0], 0.0))
                single = max(min(self.area[a_], self.area[c_]), 1.0)
                if d < cfg.split_min_px or area[b] < cfg.merge_area_ratio * single:
                    # no visible second marker: merged head-on, or one hides the other
                    self.unresolved[a_] = self.unresolved[c_] = True
                if d >= cfg.split_min_px:
                    sep = d * evec[:, 1]
                    if sep @ rel < 0:
                        sep = -sep
                else:
                    sep = rel if np.linalg.norm(rel) < 2 * blob_r[b] else rel * (2 * blob_r[b] / np.linalg.norm(rel))
                sub[a_] = uv[b] + sep / 2
                sub[c_] = uv[b] - sep / 2
            else:
                for m in ms:
                    self.unresolved[m] = True
                for m in ms:  # three or more: coast, but stay inside the blob
                    off = pred[m] - uv[b]
                    norm = float(np.linalg.norm(off))
                    sub[m] = uv[b] + (off * (blob_r[b] / norm) if norm > blob_r[b] else off)
        self._update_certainty(pred, uv, assigned, merged, groups, gate)
        # state update (plain Python floats: cheaper than numpy calls for 8 tracks)
        P, V, A = self.pos.tolist(), self.vel.tolist(), self.area.tolist()
        MI, ST = self.missing.tolist(), self.stale.tolist()
        PR, fin = pred.tolist(), finite.tolist()
        uvl, arl = uv.tolist(), area.tolist()
        alpha, beta, coast, decay = cfg.alpha, cfg.beta, cfg.coast_frames, cfg.coast_decay
        for m in range(N_MARKERS):
            b = assigned.get(m)
            if b is not None:
                z = sub[m].tolist() if m in sub else uvl[b]
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
        self.pos, self.vel, self.area = np.array(P), np.array(V), np.array(A)
        self.missing, self.stale = np.array(MI, np.int64), np.array(ST, np.int64)
        return self._output(uv, area, assigned, merged, n)

    def _doubt(self, m: int) -> None:
        if self.certain[m]:
            self.certain[m] = False
            self.uncertain_events += 1

    def _update_certainty(self, pred: np.ndarray, uv: np.ndarray, assigned: dict[int, int], merged: set[int],
                          groups: dict[int, list[int]], gate: np.ndarray) -> None:
        """Identity bookkeeping: a pair leaving a merge keeps its labels only if the split was
        unambiguous; a track back from a gap keeps its label only if no other track could
        claim its blob; the last uncertain track of eight becomes certain by elimination."""
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
                    elif k in clean and np.isfinite(pred[m]).all() and np.isfinite(pred[k]).all():
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
            elif self.missing[m] > cfg.doubt_after_gap and np.isfinite(pred[m]).all():
                others = [k for k in range(N_MARKERS) if k != m and np.isfinite(pred[k]).all()
                          and np.linalg.norm(pred[k] - uv[b]) < gate[k] + gate[m]]
                if others:
                    self._doubt(m)
        # elimination: all eight measured as separate blobs and only one of them uncertain
        unsure = np.flatnonzero(~self.certain)
        if len(unsure) == 1 and len(clean) == N_MARKERS and len(set(clean.values())) == N_MARKERS:
            self.certain[unsure[0]] = True
        self._recover(uv, assigned, clean)

    def _violations(self, pos: dict[int, np.ndarray]) -> int:
        """Body-plausibility violations of a labelling pos {marker: (2,) px} (a standing body
        seen from roughly horizontal cameras): legs clearly crossed over relative to the
        shoulder axis, a wrist out of its shoulder's reach, a shin too long, a knee or ankle
        at shoulder height."""
        bad = 0
        sh_l, sh_r = pos.get(L_SH), pos.get(R_SH)
        h = self.body_h
        if sh_l is not None and sh_r is not None:
            s = sh_l - sh_r
            w = float(np.linalg.norm(s))
            if w > 4.0:
                a = s / w
                for lm, rm in ((L_KN, R_KN), (L_AN, R_AN)):
                    if lm in pos and rm in pos and (pos[lm] - pos[rm]) @ a < -1.0 * w:
                        bad += 1
            top = 0.5 * (sh_l[1] + sh_r[1])
            for m in (L_KN, R_KN, L_AN, R_AN):
                if m in pos and pos[m][1] < top + 0.25 * h:
                    bad += 1
        for sh, wr in ((L_SH, L_WR), (R_SH, R_WR)):
            if sh in pos and wr in pos and np.linalg.norm(pos[wr] - pos[sh]) > 1.2 * self.reach_px:
                bad += 1
        for kn, an in ((L_KN, L_AN), (R_KN, R_AN)):
            if kn in pos and an in pos and np.linalg.norm(pos[kn] - pos[an]) > 1.25 * self.shin_px:
                bad += 1
        return bad

    def _recover(self, uv: np.ndarray, assigned: dict[int, int], clean: dict[int, int]) -> None:
        """Give uncertain tracks their identities back when every marker is in view, the
        uncertain ones on separate blobs, and exactly one way of labelling those blobs is
        plausible (``_violations``) for ``recover_frames`` frames in a row."""
        cfg = self.cfg
        unsure = [m for m in range(N_MARKERS) if not self.certain[m]]
        ok = (0 < len(unsure) <= 4 and self.body_h > 0 and len(assigned) == N_MARKERS
              and all(m in clean for m in unsure) and len({clean[m] for m in unsure}) == len(unsure))
        if not ok:
            self._recover_key, self._recover_streak = None, 0
            return
        fixed = {m: uv[b] for m, b in assigned.items() if self.certain[m]}
        plausible = []
        for perm in itertools.permutations(unsure):
            pos = dict(fixed)
            pos.update({lab: uv[clean[m]] for m, lab in zip(unsure, perm)})
            if self._violations(pos) == 0:
                plausible.append(perm)
                if len(plausible) > 1:
                    break
        if len(plausible) != 1:
            self._recover_key, self._recover_streak = None, 0
            return
        key = (tuple(unsure), plausible[0])
        self._recover_streak = self._recover_streak + 1 if key == self._recover_key else 1
        self._recover_key = key
        if self._recover_streak < cfg.recover_frames:
            return
        order = list(range(N_MARKERS))
        for m, lab in zip(unsure, plausible[0]):
            order[lab] = m
        for name in ("pos", "vel", "area", "missing", "stale"):
            setattr(self, name, getattr(self, name)[order].copy())
        self.certain[list(plausible[0])] = True
        self.recovered += 1
        self._recover_key, self._recover_streak = None, 0

    def _init_index(self, uv: np.ndarray) -> np.ndarray:
        D = np.linalg.norm(self.pos[:, None, :] - uv[None, :, :], axis=2)
        return D.argmin(1)

    def _output(self, uv: np.ndarray, area: np.ndarray, assigned: dict[int, int], merged: set[int], n: int) -> TrackOutput:
        """Packet records: one per marker (measured, predicted or lost; uncertain ones unlabelled),
        then every blob no track claimed (unlabelled)."""
        labels, pts, areas, flags = [], [], [], []
        uvl, arl = uv.tolist(), area.tolist()
        posl, cert, miss = self.pos.tolist(), self.certain.tolist(), self.missing.tolist()
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
            else:
                labels.append(m)
                pts.append(posl[m])
                areas.append(0)
                flags.append(FLAG_PREDICTED if miss[m] <= coast else FLAG_LOST)
        for b in range(n):
            if b not in used:
                labels.append(UNLABELLED)
                pts.append(uvl[b])
                areas.append(arl[b])
                flags.append(0)
        return TrackOutput(np.array(labels, np.uint8), np.array(pts, np.float32).reshape(-1, 2),
                           np.clip(np.array(areas), 0, 65535).astype(np.uint16), np.array(flags, np.uint8))

    @staticmethod
    def _unlabelled(uv: np.ndarray, area: np.ndarray) -> TrackOutput:
        n = len(uv)
        return TrackOutput(np.full(n, UNLABELLED, np.uint8), uv.astype(np.float32),
                           np.clip(area, 0, 65535).astype(np.uint16), np.zeros(n, np.uint8))
