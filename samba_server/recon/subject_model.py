"""Subject estimation pieces shared by the offline calibration and the live reconstructor.

- :func:`linear_update`: with the per-frame torso rotation R_f, shoulder midpoint o_f and bone
  directions D_f fixed, every marker is linear in the bone lengths and the offsets:
  ``m_fi = o_f + R_f (A_i(D_f) lengths + S_i(D_f) offset_i)``. One regularised least-squares
  solve (o_f eliminated per frame) with Gaussian priors gives lengths, offsets and their
  posterior sigmas.
- :func:`placement_from_standard_pose`: skin landmarks or joint centres, from the hip width the
  standard pose implies under each hypothesis.

No import of :mod:`.reconstruct` here: the reconstructor uses this module live
(:mod:`.subject_fit` wraps it offline).
"""

from __future__ import annotations

import numpy as np

from samba_common.body import fk_body
from samba_common.markerset import OFFSET_SIGMA, TYPICAL_OFFSETS, segment_frames_body
from samba_common.skeleton import BONE_TYPES, MARKER_JOINT, N_MARKERS

from .proportions import _dist, _robust, approximate_centres, standard_pose_frames

#: prior standard deviation (m) of each bone length about its start value (BONE_TYPES order);
#: the neck has no marker and keeps its start value
LENGTH_SIGMA = np.array([0.03, 0.015, 0.015, 0.003, 0.01, 0.01, 0.015, 0.03])

#: seconds over which consecutive frames' marker errors are correlated (pose-solve error and
#: soft-tissue wobble both move slowly): frames closer than this do not count as independent
CORRELATION_S = 0.2
#: multiplies the least-squares posterior sigma (then capped at the prior's): the poses the
#: update holds fixed absorb part of the offsets (the pose solve's prior pulls them), which the
#: least-squares sigma ignores. Measured on 6 simulated takes (synthetic motion, not the
#: benchmark clips): the raw sigma (~2 mm) was 4.6x smaller than the rms error (~5 mm);
#: benchmarks/accuracy.py checks rms(error / sigma) on the CMU clips
SIGMA_INFLATION = 4.5
#: standard deviation (m) of one side's lateral knee / ankle offset about the two sides' mean
LATERAL_ASYMMETRY = 0.003
#: the standard pose's hip width and lateral leg offsets are held (their prior precision times
#: this): the solved poses of the motion are biased on exactly these (the pose prior prefers a
#: leg abduction, and a lateral offset trades against it), and let free the update moved them
#: ~1 cm the wrong way on simulated takes (tests/recon/test_subject.py's synthetic motion)
STANDARD_POSE_WEIGHT = 100.0


def linear_update(markers: np.ndarray, R: np.ndarray, o: np.ndarray, dirs: np.ndarray, lengths0: np.ndarray,
                  sigma_data: float, decorrelate: float, offsets0: np.ndarray | None = None,
                  leg_prior: tuple[np.ndarray, np.ndarray] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One least-squares update of lengths and offsets given solved poses.

    markers: (n, 8, 3) world metres (NaN = unseen) of the solved frames; R: (n, 3, 3) torso
    rotations; o: (n, 3) shoulder midpoints (m); dirs: (n, 11, 3) unit bone directions;
    lengths0: (8,) prior centre of the lengths (m); sigma_data: marker error (m); decorrelate:
    how many frames count as one independent observation (>= 1); offsets0: (8, 3) prior centre
    of the offsets (m, default TYPICAL_OFFSETS); leg_prior: the standard pose's Gaussian of the
    hip width and the lateral knee / ankle departures (mean (3,), covariance (3, 3); from
    :func:`.proportions.skin_leg_fit`), which replaces the independent priors of the hip width and
    the four lateral leg offsets: the motion barely separates them (a lateral offset trades against
    the hip width and the leg's abduction), the standard pose does.
    Returns lengths (8,), offsets (8, 3), their 1-sigma (8,), (8, 3) (m; offsets' sigma
    inflated by :data:`SIGMA_INFLATION`).
    """
    n = len(R)
    nl = len(BONE_TYPES)
    A = np.stack([fk_body(dirs, np.eye(nl)[k])[:, list(MARKER_JOINT)] for k in range(nl)], axis=-1)  # (n, 8, 3, 8)
    S = segment_frames_body(dirs)  # (n, 8, 3, 3)
    B = np.zeros((n, N_MARKERS, 3, nl + 3 * N_MARKERS))
    B[..., :nl] = A
    for i in range(N_MARKERS):
        B[:, i, :, nl + 3 * i: nl + 3 * i + 3] = S[:, i]
    y = np.einsum("fji,fmj->fmi", R, markers - o[:, None, :])  # observations in torso coordinates
    seen = np.all(np.isfinite(y), axis=2)
    y = np.where(seen[..., None], y, 0.0)
    cnt = np.maximum(seen.sum(axis=1), 1)[:, None]
    y_mean = y.sum(axis=1) / cnt
    B_mean = np.einsum("fm,fmck->fck", seen.astype(float), B) / cnt[:, :, None]
    yc = (y - y_mean[:, None]) * seen[..., None]
    Bc = (B - B_mean[:, None]) * seen[..., None, None]
    Bc = Bc.reshape(-1, B.shape[-1])
    yc = yc.reshape(-1)
    w = 1.0 / (sigma_data ** 2 * decorrelate)
    off0 = TYPICAL_OFFSETS if offsets0 is None else np.asarray(offsets0, dtype=float)
    prior_mu = np.concatenate([lengths0, off0.reshape(-1)])
    prior_sig = np.concatenate([LENGTH_SIGMA, OFFSET_SIGMA.reshape(-1)])
    P = np.diag(1.0 / prior_sig ** 2)
    if leg_prior is not None and np.all(np.isfinite(leg_prior[1])):
        idx = [1] + [nl + 3 * i for i in (4, 5, 6, 7)]  # hip width, e1 of the knees and ankles
        Mmap = np.array([[1, 0, 0], [0, 1, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]], float)
        cov = Mmap @ np.asarray(leg_prior[1], float) @ Mmap.T + np.diag([0.0] + [LATERAL_ASYMMETRY ** 2] * 4)
        P[np.ix_(idx, idx)] = STANDARD_POSE_WEIGHT * np.linalg.inv(cov)
    H = w * Bc.T @ Bc + P
    g = w * Bc.T @ yc + P @ prior_mu
    theta = np.linalg.solve(H, g)
    sig = np.sqrt(np.diag(np.linalg.inv(H)))
    sig_o = np.minimum(SIGMA_INFLATION * sig[nl:], OFFSET_SIGMA.reshape(-1))
    if leg_prior is not None and np.all(np.isfinite(leg_prior[1])):  # held: report the standard pose's sigma
        sig_o[[3 * i for i in (4, 5, 6, 7)]] = np.minimum(np.sqrt(np.diag(cov)[1:]), OFFSET_SIGMA[4:, 0])
    lengths = np.maximum(theta[:nl], 0.2 * np.asarray(lengths0, float))
    return lengths, theta[nl:].reshape(N_MARKERS, 3), sig[:nl], sig_o.reshape(N_MARKERS, 3)


def decorrelation(t: np.ndarray) -> float:
    """Frames per independent observation for solved frames at times ``t`` (n,) seconds."""
    if len(t) < 2:
        return 1.0
    dt = float(np.median(np.abs(np.diff(t))))
    return max(1.0, CORRELATION_S / max(dt, 1e-3))


def placement_from_standard_pose(markers: np.ndarray, db_lengths: np.ndarray) -> tuple[str, str, int] | None:
    """Skin landmarks or joint centres, from the standard pose; None without one (< 5 frames).

    markers: (F, 8, 3) world metres; db_lengths: (8,) database body. Legs straight below the
    hips, the hip width is the knee spacing extrapolated past the ankles; taken as joint centres,
    skin markers give hips about 10 cm too wide, and the other way round about 10 cm too narrow.
    The hypothesis whose hip width is nearer the one the observed proportions (shoulder width,
    shin, arm) predict wins. Returns (placement, reason, standard-pose frames)."""
    markers = np.asarray(markers, dtype=float)
    dbl = np.asarray(db_lengths, dtype=float)
    sw = _robust(_dist(markers, "left_shoulder", "right_shoulder"))
    shin = _robust(np.concatenate([_dist(markers, "left_knee", "left_ankle"), _dist(markers, "right_knee", "right_ankle")]))
    arm = _robust(np.concatenate([_dist(markers, "left_shoulder", "left_wrist"),
                                  _dist(markers, "right_shoulder", "right_wrist")]), 97.0)
    if not np.all(np.isfinite([sw, shin, arm])) or min(sw, shin, arm) <= 0:
        return None
    scale = np.exp(np.mean(np.log([sw / dbl[0], shin / dbl[7], arm / (dbl[4] + dbl[5])])))
    expected = float(dbl[1] * scale)
    as_skin = approximate_centres(markers, TYPICAL_OFFSETS)  # a hanging skin arm looks ~5 % longer
    arm_skin = _robust(np.concatenate([_dist(as_skin, "left_shoulder", "left_wrist"),
                                       _dist(as_skin, "right_shoulder", "right_wrist")]), 97.0)
    stand = standard_pose_frames(markers, arm) | standard_pose_frames(as_skin, arm_skin)
    if stand.sum() < 5:
        return None
    ratio = dbl[6] / dbl[7]

    def hip(m: np.ndarray) -> float:
        knee, ankle = _dist(m, "left_knee", "right_knee"), _dist(m, "left_ankle", "right_ankle")
        return _robust(knee - (ankle - knee) * ratio)

    h_jc, h_skin = hip(markers[stand]), hip(as_skin[stand])

    def miss(h: float) -> float:  # the offsets add to the hip width: compare differences, not ratios
        return abs(h - expected) if np.isfinite(h) else np.inf

    if not (np.isfinite(miss(h_jc)) or np.isfinite(miss(h_skin))):
        return None
    placement = "joint_centres" if miss(h_jc) < miss(h_skin) else "skin"
    reason = (f"standard pose ({int(stand.sum())} frames): hip width {100 * h_jc:.1f} cm if the markers were "
              f"joint centres, {100 * h_skin:.1f} cm if skin landmarks; the proportions predict "
              f"{100 * expected:.1f} cm")
    return placement, reason, int(stand.sum())


__all__ = ["LENGTH_SIGMA", "SIGMA_INFLATION", "decorrelation", "linear_update", "placement_from_standard_pose"]
