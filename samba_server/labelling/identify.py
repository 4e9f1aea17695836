"""Naming unlabelled 3D points as the 8 markers with no prediction: acquisition and recovery.

Used for the first labelling of a take (the standard pose, any stance) and whenever the
labels are lost (a blackout, the subject leaving and re-entering, a jump). The shoulders are
the pair of high points a shoulder width apart; each ordering of the pair is one facing
(the subject's right = facing x up). Legs are knee-ankle pairs a shin length apart, within
reach of their side's shoulder; wrists are points within an arm of their shoulder. Every
labelling these rigid lengths allow is scored:

- +1 per marker named (a hidden marker may stay unnamed; a merged point shared by both knees
  or both ankles names two),
- rigid-length errors, and trust in the points (2-view points that other views should have seen),
- facing: agreement with the facing the subject had (the standard pose faces +Y; after a
  loss, the last facing, trusted less the longer ago) and with the direction of travel,
- anatomy: knees bend backwards and hang about a trunk below the shoulders, the left leg is on
  the left.

The best labelling wins; its margin over the runner-up tells how sure the naming is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from .rigid import LA, LEVEL_M, LK, LS, LW, RA, RK, RS, RW, Body

__all__ = ["Hint", "Hypothesis", "identify", "right_of", "score_labels", "sized"]

_UP = np.array([0.0, 0.0, 1.0])
#: a right knee (ankle) less than _LATERAL_M m to the subject's right of the left one costs
#: _LATERAL_W per metre: legs cross little, so a swapped pair costs about 1
_LATERAL_W, _LATERAL_M = 4.0, 0.03
#: a pair named crossed before the names were lost costs _HELD_W per metre side by side (the
#: subject may have moved the feet meanwhile: less than a pair side by side costs crossed)
_HELD_W = 2.0
#: knees and ankles in opposite lateral orders (each pair more than _LATERAL_M apart) cost _CROSS_W
_CROSS_W = 0.4
#: shoulders more than _TILT_M m apart in height cost _TILT_W per metre (a wrist at shoulder
#: height a shoulder width away is not a shoulder)
_TILT_W, _TILT_M = 10.0, LEVEL_M
#: an ankle named without its knee more than _HIGH_ANKLE_M m above the floor costs
#: _HIGH_ANKLE_W per metre
_HIGH_ANKLE_W, _HIGH_ANKLE_M = 2.0, 0.25
#: score of the second marker a shared point names (a separate point naming it scores 1)
_SHARED_NAME = 0.4
#: a knee nearer its shoulder than _NEAR_F trunks costs _NEAR_W per metre (at most 2)
_NEAR_W, _NEAR_F = 8.0, 0.75
#: before the subject is measured, the prior body is scaled to the shoulders' height within these
_SCALE_LO, _SCALE_HI, _SCALE_FREE = 0.7, 1.2, 0.1


@dataclass
class Hint:
    """What is known about the subject besides the points.

    facing: (2,) unit horizontal facing direction, or None; facing_weight: how much it counts;
    facing_slack: radians the subject may have turned since (a facing within it of the known
    one costs nothing); velocity: (3,) m/s of the body's centre over the last frames, or None;
    labels: (8,) point per marker that tracking named (-1 = none), each agreeing name adding
    labels_weight; crossed: (knees, ankles) last named crossed (the right one left of the left
    one) just before the names were lost: that pair is expected crossed, not side by side.
    """

    facing: np.ndarray | None = None
    facing_weight: float = 0.0
    facing_slack: float = 0.0
    velocity: np.ndarray | None = None
    labels: np.ndarray | None = None
    labels_weight: float = 0.0
    crossed: tuple[bool, bool] = (False, False)

    def agree(self, marker: int, point: int) -> float:
        """Bonus for naming point as marker when tracking did too."""
        if self.labels is None or point < 0:
            return 0.0
        return self.labels_weight if self.labels[marker] == point else 0.0


@dataclass
class Hypothesis:
    """labels: (8,) point index per marker (-1 = unnamed); score; facing (2,) unit."""

    labels: np.ndarray
    score: float
    facing: np.ndarray


def right_of(facing: np.ndarray) -> np.ndarray:
    """(3,) horizontal unit vector to the subject's right of a (2,) unit facing (right = facing x up)."""
    return np.array([facing[1], -facing[0], 0.0])


def _unit2(v: np.ndarray) -> np.ndarray | None:
    n = float(np.hypot(v[0], v[1]))
    return None if n < 1e-6 else np.array([v[0], v[1]]) / n


#: m an ankle may lie above its knee (a shin held level: a leg raised behind, a kick)
ANKLE_ABOVE_M = 0.1


def _ankle_above_knee(X: np.ndarray, k: int, a: int) -> bool:
    """Ankle point a lies more than ANKLE_ABOVE_M above knee point k: not one leg."""
    return bool(X[a, 2] > X[k, 2] + ANKLE_ABOVE_M)


def _distances(X: np.ndarray, idx: list[int]) -> np.ndarray:
    """(M, M) distance (m) between the points idx of X (M, 3), each as ``np.linalg.norm`` of
    their difference gives it (NaN for the points not in idx)."""
    D = np.full((len(X), len(X)), np.nan)
    for n, i in enumerate(idx):
        D[i, i] = 0.0
        for j in idx[n + 1:]:
            D[i, j] = D[j, i] = float(np.linalg.norm(X[i] - X[j]))
    return D


def _leg_penalty(X: np.ndarray, D: np.ndarray, s: int, k: int, a: int, body: Body) -> float | None:
    """Penalty of knee point k and ankle point a (-1 = unnamed) for the side whose shoulder is
    point s, or None when the rigid lengths do not allow them. D: :func:`_distances`."""
    reach_k = body.trunk + 2 * body.tol
    reach_a = reach_k + body.shin
    top = X[s, 2]
    if k < 0:
        if a < 0:
            return 0.0
        if D[a, s] > reach_a or X[a, 2] >= top - 0.6:
            return None
        # an ankle whose knee is not named stays near the floor: a point at knee height named
        # an ankle (leaving the real ankle below it unnamed) costs
        return _HIGH_ANKLE_W * max(0.0, float(X[a, 2]) - _HIGH_ANKLE_M)
    dk = D[k, s]
    if dk > reach_k or X[k, 2] > top - 0.2:
        return None
    # the knee hangs about a trunk (torso + thigh) below its shoulder: much nearer takes a
    # deep crouch, or a wrist taken for the shoulder
    near = min(2.0, _NEAR_W * max(0.0, _NEAR_F * body.trunk - dk))
    if a < 0:
        return near
    if a == k or _ankle_above_knee(X, k, a):
        return None
    err = abs(D[k, a] - body.shin)
    if err > body.tol or D[a, s] > reach_a:
        return None
    return near + 0.3 * (err / body.tol) ** 2


def _leg_options(X: np.ndarray, D: np.ndarray, free: list[int], s: int, body: Body) -> list[tuple[int, int, float]]:
    """(knee, ankle, penalty) options for the side whose shoulder is point s: pairs a shin
    apart, single points, or nothing. D: :func:`_distances`."""
    out: list[tuple[int, int, float]] = [(-1, -1, 0.0)]
    for k in free:
        pen_k = _leg_penalty(X, D, s, k, -1, body)
        if pen_k is None:
            continue
        out.append((k, -1, pen_k))
        for a in free:
            pen = _leg_penalty(X, D, s, k, a, body)
            if pen is not None:
                out.append((k, a, pen))
    for a in free:
        pen_a = _leg_penalty(X, D, s, -1, a, body)
        if pen_a is not None:
            out.append((-1, a, pen_a))
    return out


def sized(body: Body, left: np.ndarray, right: np.ndarray, lowest: float = 0.0) -> Body:
    """The body to name the rest by, with the shoulders at left, right (3,) m: a measured body
    as it is; before the subject is measured, the prior body scaled to the shoulders' height (as
    if standing, between _SCALE_LO and _SCALE_HI of the prior's) less _SCALE_FREE, the prior's own
    spread (a body within it is taken as the prior). A child in the standard pose (1.3 m tall,
    shoulders 0.29 m apart) fitted the database's adult body better with a shoulder and a wrist
    taken for the shoulders. lowest: the height (m) of the frame's lowest point; above
    _HIGH_ANKLE_M the feet are not seen on the floor (a subject up on a structure, or the feet
    hidden), so the shoulders' height says nothing of a larger body: never scaled up then."""
    if body.measured or body.stand <= 0:
        return body
    hi = _SCALE_HI if lowest <= _HIGH_ANKLE_M else 1.0
    s = min(hi, max(_SCALE_LO, 0.5 * float(left[2] + right[2]) / body.stand))
    s = 1.0 + math.copysign(max(0.0, abs(s - 1.0) - _SCALE_FREE), s - 1.0)
    return body if s == 1.0 else body.scaled(s)


def _shoulders(X: np.ndarray, L: int, R: int, trust: np.ndarray, body: Body, hint: Hint) -> tuple[float, np.ndarray] | None:
    """(score, facing (2,)) of points L, R as the left and right shoulders, or None when they
    cannot be."""
    zs = X[:, 2]
    # no higher than a jump lifts them (points up there are the knees of a subject standing on
    # something, the upper body out of view)
    if min(zs[L], zs[R]) < 0.6 or max(zs[L], zs[R]) > body.top or abs(zs[L] - zs[R]) > 0.35 \
            or body.width_error(X[L], X[R]) > body.tol:
        return None
    f = _unit2(np.cross(_UP, X[R] - X[L]))
    if f is None:
        return None
    base = 2.0 - 0.3 * (body.width_error(X[L], X[R]) / body.tol) ** 2 - trust[L] - trust[R]
    base -= _TILT_W * max(0.0, abs(float(X[L, 2] - X[R, 2])) - _TILT_M)  # shoulders stay level
    base += hint.agree(LS, L) + hint.agree(RS, R)
    if hint.facing is not None:
        turn = math.acos(max(-1.0, min(1.0, float(f @ hint.facing))))
        base -= hint.facing_weight * (1.0 - math.cos(max(0.0, turn - hint.facing_slack)))
    if hint.velocity is not None and np.hypot(*hint.velocity[:2]) > 0.5:
        v = hint.velocity[:2] / np.hypot(*hint.velocity[:2])
        base -= 1.5 * max(0.0, -float(f @ v) - 0.2)
    return base, f


def _legs_score(X: np.ndarray, trust: np.ndarray, L: int, R: int, left: tuple[int, int, float],
                right: tuple[int, int, float], f: np.ndarray, shared: np.ndarray,
                hint: Hint) -> tuple[float, int, int, int, int] | None:
    """(score, kl, al, kr, ar) of one leg option per side (from :func:`_leg_options`), or None
    when they use a point twice."""
    kl, al, pl = left
    kr, ar, pr = right
    used = [p for p in (kl, al, kr, ar) if p >= 0]
    if len(set(used)) < len(used):
        return None
    r = right_of(f)[:2]
    sc = len(used) - pl - pr - sum(trust[p] for p in used)
    sc -= 2.0 * (_knee_bend(X, X[L], kl, al, f) + _knee_bend(X, X[R], kr, ar, f))
    side = []
    for a, b, crossed in ((kl, kr, hint.crossed[0]), (al, ar, hint.crossed[1])):
        if a >= 0 and b >= 0:
            side.append(float((X[b] - X[a])[:2] @ r))
            # the left one on the left, or (less surely) the order it had, crossed, just before
            # the names were lost
            if crossed:
                sc -= _HELD_W * max(0.0, _LATERAL_M + side[-1])
            else:
                sc -= _LATERAL_W * max(0.0, _LATERAL_M - side[-1])
    if len(side) == 2 and side[0] * side[1] < 0 and min(abs(side[0]), abs(side[1])) > _LATERAL_M \
            and not any(hint.crossed):
        sc -= _CROSS_W  # the knees in one order, the ankles in the other: the legs cross
    kl, kr = _share(kl, kr, shared)
    al, ar = _share(al, ar, shared)
    for k, a in ((kl, al), (kr, ar)):
        if k >= 0 and a >= 0 and _ankle_above_knee(X, k, a):
            return None  # shared across the sides, a knee point ended up below its ankle's
    # a shared point names two markers, a little less surely than two points do (int: numpy
    # bools add as "or")
    sc += _SHARED_NAME * (int(kl == kr >= 0) + int(al == ar >= 0))
    sc += hint.agree(LK, kl) + hint.agree(LA, al) + hint.agree(RK, kr) + hint.agree(RA, ar)
    return sc, kl, al, kr, ar


def _wrists_score(X: np.ndarray, trust: np.ndarray, L: int, R: int, a: int, b: int, f: np.ndarray,
                  hint: Hint) -> float:
    """Score of wrist points a, b (-1 = unnamed; each within reach of its shoulder)."""
    s = sum(1.0 - trust[w] for w in (a, b) if w >= 0) + hint.agree(LW, a) + hint.agree(RW, b)
    if a >= 0 and b >= 0:
        s -= 0.3 * max(0.0, -float((X[b] - X[a])[:2] @ right_of(f)[:2]) - 0.1)
    return s


def _share(left: int, right: int, shared: np.ndarray) -> tuple[int, int]:
    """A merged point named for one side only is named for both."""
    if left < 0 and right >= 0 and shared[right]:
        return right, right
    if right < 0 and left >= 0 and shared[left]:
        return left, left
    return left, right


def _knee_bend(X: np.ndarray, s: np.ndarray, k: int, a: int, f: np.ndarray) -> float:
    """How far the shank bends forwards relative to the thigh (0 for a normal knee)."""
    if k < 0 or a < 0:
        return 0.0
    hip = s - np.array([0.0, 0.0, 0.5])
    u = X[k] - hip
    w = X[a] - X[k]
    u /= max(np.linalg.norm(u), 1e-9)
    w /= max(np.linalg.norm(w), 1e-9)
    return max(0.0, float((w - u)[:2] @ f) - 0.15)


def identify(X: np.ndarray, trust: np.ndarray, body: Body, hint: Hint | None = None,
             shared: np.ndarray | None = None, max_points: int = 12, keep: int = 8,
             legs_kept: int = 24) -> list[Hypothesis]:
    """Labellings of points X (M, 3) world metres, best first (at most ``keep``).

    trust: (M,) penalty in [0, 1] per point (0 = sure it is a marker, e.g. seen by >= 3
    views). shared: (M,) bool, points that may stand for both knees or both ankles (seen only
    in merged blobs): such a point named for one side with the other side unnamed is named
    for both (the caller splits it). legs_kept: leg labellings per shoulder pair completed
    with wrists. Needs both shoulders; returns [] when no pair of points can be the shoulders.
    """
    shared = np.zeros(len(X), bool) if shared is None else np.asarray(shared, bool)
    hint = hint or Hint()
    M = len(X)
    if M < 2:
        return []
    idx = [int(i) for i in np.argsort(trust, kind="stable")[:max_points]]
    D = _distances(X, idx)
    hyps: dict[tuple, Hypothesis] = {}
    lowest = float(X[:, 2].min())
    # a shoulder's leg options with the body as it is (a measured subject), over every other
    # point: a pair of shoulders takes those that do not use the other shoulder
    options: dict[int, list[tuple[int, int, float]]] = {}

    def legs(s: int, other: int, free: list[int], pb: Body) -> list[tuple[int, int, float]]:
        if pb is not body:
            return _leg_options(X, D, free, s, pb)
        if s not in options:
            options[s] = _leg_options(X, D, [p for p in idx if p != s], s, pb)
        return [o for o in options[s] if o[0] != other and o[1] != other]

    for i, j in combinations(idx, 2):
        for L, R in ((i, j), (j, i)):
            pb = sized(body, X[L], X[R], lowest)
            sh = _shoulders(X, L, R, trust, pb, hint)
            if sh is None:
                continue
            base, f = sh
            free = [p for p in idx if p not in (L, R)]
            legs_l = legs(L, R, free, pb)
            legs_r = legs(R, L, free, pb)
            pairs = [p for p in (_legs_score(X, trust, L, R, ol, orr, f, shared, hint) for ol in legs_l for orr in legs_r)
                     if p is not None]
            pairs.sort(key=lambda p: -p[0])
            lim = pb.reach + pb.tol
            for sc, kl, al, kr, ar in pairs[:legs_kept]:
                taken = {L, R, kl, al, kr, ar}
                rest = [p for p in free if p not in taken]
                wl = [-1] + [p for p in rest if D[p, L] <= lim]
                wr = [-1] + [p for p in rest if D[p, R] <= lim]
                for a in wl:
                    for b in wr:
                        if a >= 0 and a == b:
                            continue
                        s = base + sc + _wrists_score(X, trust, L, R, a, b, f, hint)
                        key = [-1] * 8
                        key[LS], key[RS], key[LW], key[RW], key[LK], key[RK], key[LA], key[RA] = \
                            L, R, a, b, kl, kr, al, ar
                        key = tuple(key)
                        if key not in hyps or hyps[key].score < s:
                            hyps[key] = Hypothesis(np.array(key, np.int64), float(s), f)
    out = sorted(hyps.values(), key=lambda h: -h.score)
    return out[:keep]


def score_labels(X: np.ndarray, trust: np.ndarray, body: Body, hint: Hint | None, labels: np.ndarray,
                 shared: np.ndarray | None = None) -> float | None:
    """The score :func:`identify` gives a labelling (8,) of points X (M, 3) (-1 = unnamed;
    both knees or both ankles may name one shared point), for comparing a tracked labelling
    with a fresh identification: the best score of the labelling or of it with legs left out
    (markers the rigid lengths rule out count as unnamed). None when the shoulders are not
    both named or cannot be shoulders."""
    shared = np.zeros(len(X), bool) if shared is None else np.asarray(shared, bool)
    hint = hint or Hint()
    L, R = int(labels[LS]), int(labels[RS])
    if L < 0 or R < 0 or L == R:
        return None
    body = sized(body, X[L], X[R], float(X[:, 2].min()))
    sh = _shoulders(X, L, R, trust, body, hint)
    if sh is None:
        return None
    base, f = sh
    D = _distances(X, sorted({int(p) for p in labels if p >= 0}))

    def options(s: int, k: int, a: int) -> list[tuple[int, int, float]]:
        out = []
        for kk, aa in {(k, a), (k, -1), (-1, a), (-1, -1)}:
            pen = _leg_penalty(X, D, s, kk, aa, body)
            if pen is not None:
                out.append((kk, aa, pen))
        return out

    kl, kr, al, ar = (int(labels[m]) for m in (LK, RK, LA, RA))
    best = -np.inf
    # a point named for both knees (ankles) is one side's, shared (identify names it so)
    for kl_, kr_ in {(kl, kr if kr != kl else -1), (kl if kl != kr else -1, kr)}:
        for al_, ar_ in {(al, ar if ar != al else -1), (al if al != ar else -1, ar)}:
            for ol in options(L, kl_, al_):
                for orr in options(R, kr_, ar_):
                    p = _legs_score(X, trust, L, R, ol, orr, f, shared, hint)
                    if p is not None:
                        best = max(best, p[0])
    reach = body.reach + body.tol
    a, b = (int(labels[m]) for m in (LW, RW))
    a = a if a >= 0 and a not in labels[[LS, RS, LK, RK, LA, RA]] and np.linalg.norm(X[a] - X[L]) <= reach else -1
    b = b if b >= 0 and b != a and b not in labels[[LS, RS, LK, RK, LA, RA]] and np.linalg.norm(X[b] - X[R]) <= reach else -1
    return float(base + best + _wrists_score(X, trust, L, R, a, b, f, hint))
