"""Subject proportions: the 8 bone lengths of the person in a take.

Observed directly by the markers: shoulder width, shin, and the whole arm (shoulder–wrist when
the arm is straight). Not observed: the split of the arm into upper arm and forearm, the hips
(so torso, thigh and hip width) and the head (neck). Those come from the database's
proportions as a prior, scaled by what the take shows:

- upper arm + forearm = a high percentile of the shoulder–wrist distance, split in the database
  ratio;
- torso + thigh = a high percentile of the shoulder-midpoint–knee distance (upright, legs
  straight: the standard pose at the start of every take), split in the database ratio after
  removing the sideways hip offset;
- hip width: from the knee and ankle spacing in the standard pose (legs straight, so the hip
  spacing is the knee spacing extrapolated past the ankles; for skin landmarks a Gaussian fit
  with the proportions' hip width and the typical lateral offsets as priors, :func:`skin_leg_fit`),
  else database value × scale;
- neck = database value × the mean scale of the observed bones.

:func:`estimate_lengths` does this on a whole take (or its first second live); the
reconstructor's whole-take refinement (:func:`samba_server.recon.reconstruct.refine_lengths`) then
adjusts the unobserved split with the evidence of every frame.
"""

from __future__ import annotations

import logging

import numpy as np

from samba_common.body import L
from samba_common.skeleton import M

log = logging.getLogger(__name__)


class ProportionError(ValueError):
    """The take does not show enough of the body to estimate its proportions."""


def _dist(markers: np.ndarray, a: str, b: str) -> np.ndarray:
    return np.linalg.norm(markers[:, M[a]] - markers[:, M[b]], axis=-1)


def _robust(values: np.ndarray, q: float | None = None) -> float:
    v = values[np.isfinite(values)]
    if v.size == 0:
        return float("nan")
    return float(np.median(v) if q is None else np.percentile(v, q))


def standard_pose_frames(markers: np.ndarray, arm: float) -> np.ndarray:
    """Boolean (F,): frames that look like the standard pose (arms straight and level, knees and
    ankles below the hips). arm: the subject's shoulder-wrist length when straight (m)."""
    with np.errstate(invalid="ignore"):
        ok = np.ones(len(markers), bool)
        for side in ("left", "right"):
            s, w = markers[:, M[f"{side}_shoulder"]], markers[:, M[f"{side}_wrist"]]
            ok &= np.linalg.norm(s - w, axis=-1) > 0.95 * arm
            ok &= np.abs(s[:, 2] - w[:, 2]) < 0.15 * arm
            k, a = markers[:, M[f"{side}_knee"]], markers[:, M[f"{side}_ankle"]]
            leg = k - a
            ok &= leg[:, 2] > 0.95 * np.linalg.norm(leg, axis=-1)
            ok &= s[:, 2] > k[:, 2]
    return ok


def approximate_centres(markers: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Markers (F, 8, 3) moved to approximate joint centres by removing ``offsets`` (8, 3)
    (samba_common.markerset frames) as if the subject stood upright in the standard pose: lateral
    along the shoulder line, up along world Z, forward = shoulder line x Z; the wrists' dorsal
    axis is up. Exact in the standard pose; a start for the whole-take fit otherwise."""
    m = np.array(markers, dtype=float)
    x = m[:, M["left_shoulder"]] - m[:, M["right_shoulder"]]
    x[:, 2] = 0.0
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    x = np.where(n > 1e-9, x / np.where(n > 1e-9, n, 1.0), np.array([-1.0, 0.0, 0.0]))  # facing +Y: left = -X
    z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), x.shape)
    fwd = np.cross(x, z)
    for i in range(8):
        s = 1.0 if i % 2 == 0 else -1.0
        a = np.asarray(offsets[i], dtype=float)
        if i in (M["left_wrist"], M["right_wrist"]):  # e1 dorsal = up, e2 proximal = towards the body
            w = a[0] * z - a[1] * s * x + a[2] * fwd
        else:  # e1 lateral, e2 up, e3 forward
            w = a[0] * s * x + a[1] * z + a[2] * fwd
        m[:, i] -= w
    return m


#: relative standard deviation of the hip width about the database proportion scaled by the
#: subject's observed bones (shoulder width, shin, arm)
HIP_PROPORTION_SIGMA = 0.06
#: standard deviation (rad) of each leg's sideways tilt in the standard pose (legs about vertical)
STANCE_SIGMA = 0.03
#: knee and ankle marker spacing (typical offsets removed) differing by more than this (m): the
#: legs are apart (about 2.5 degrees each), not the standard pose's
LEGS_APART = 0.04
#: standard deviation (m) of the median knee (ankle) marker spacing over the standard pose
SPACING_NOISE = 0.002


def skin_leg_fit(knee_sep: float, ankle_sep: float, hip_prior: float, thigh: float, shin: float,
                 lateral_sigma: float = 0.008) -> tuple[np.ndarray, np.ndarray]:
    """Hip width and lateral knee/ankle offsets (m) from the standard pose, for skin landmarks.

    knee_sep, ankle_sep: spacing (m) of the knee and of the ankle markers with the typical lateral
    offsets removed; hip_prior: the proportions' hip width (m); thigh, shin: lengths (m);
    lateral_sigma: prior sigma (m) of a lateral offset about the typical one.
    Extrapolating the knee spacing past the ankles (exact for joint centres) multiplies a lateral
    offset's error by ~4 (a 7 mm wider epicondyle gave 3 cm wider hips). Instead one Gaussian
    least-squares fit of the hip width h, the legs' sideways tilt a and the lateral offsets'
    departures dk, da from the typical ones (both sides alike): knee spacing = h + 2 thigh a + 2 dk,
    ankle spacing = h + 2 (thigh + shin) a + 2 da, with priors h ~ hip_prior
    (:data:`HIP_PROPORTION_SIGMA`), a ~ 0 (:data:`STANCE_SIGMA`), dk, da ~ 0 (lateral_sigma).
    Returns the posterior mean (3,) of (h, dk, da) and its covariance (3, 3) (the tilt
    marginalised); NaNs when the spacings are unknown.
    """
    if not (np.isfinite(knee_sep) and np.isfinite(ankle_sep) and np.isfinite(hip_prior)):
        return np.full(3, np.nan), np.full((3, 3), np.nan)
    J = np.array([[1.0, 2.0 * thigh, 2.0, 0.0], [1.0, 2.0 * (thigh + shin), 0.0, 2.0]])
    w = 1.0 / SPACING_NOISE ** 2
    prior_sig = np.array([HIP_PROPORTION_SIGMA * hip_prior, STANCE_SIGMA, lateral_sigma, lateral_sigma])
    prior_mu = np.array([hip_prior, 0.0, 0.0, 0.0])
    H = w * J.T @ J + np.diag(1.0 / prior_sig ** 2)
    g = w * J.T @ np.array([knee_sep, ankle_sep]) + prior_mu / prior_sig ** 2
    keep = [0, 2, 3]
    return np.linalg.solve(H, g)[keep], np.linalg.inv(H)[np.ix_(keep, keep)]


def estimate_lengths(markers: np.ndarray, db_lengths: np.ndarray, offsets: np.ndarray | None = None,
                     straight_percentile: float = 97.0) -> np.ndarray:
    """Bone lengths (8,) metres of the subject in ``markers`` (F, 8, 3) (NaN = missing); see
    :func:`estimate_start` (this is its lengths)."""
    return estimate_start(markers, db_lengths, offsets, straight_percentile)[0]


def estimate_start(markers: np.ndarray, db_lengths: np.ndarray, offsets: np.ndarray | None = None,
                   straight_percentile: float = 97.0
                   ) -> tuple[np.ndarray, np.ndarray | None, tuple[np.ndarray, np.ndarray] | None]:
    """Bone lengths (8,) metres of the subject in ``markers`` (F, 8, 3) (NaN = missing).

    db_lengths: (8,) the database body's lengths, used as the proportion prior. offsets: (8, 3)
    marker offsets (samba_common.markerset), removed first by :func:`approximate_centres`.
    Returns the lengths (8,) and the offsets (8, 3) with the lateral knee and ankle components
    refined from the standard pose (:func:`skin_leg_fit`; a copy of ``offsets`` without a standard
    pose, None for joint centres) and that fit's Gaussian (mean (3,), covariance (3, 3)) of the
    hip width and the lateral knee and ankle departures, m (None without an upright standard pose).
    Raises ProportionError when shoulders, shins or arms are never seen.
    """
    skin = offsets is not None and bool(np.any(offsets))
    offsets_out = np.array(offsets, dtype=float) if skin else None
    leg_prior: tuple[np.ndarray, np.ndarray] | None = None
    db = np.asarray(db_lengths, dtype=float)
    if skin:
        markers = approximate_centres(markers, offsets)
    sw = _robust(_dist(markers, "left_shoulder", "right_shoulder"))
    shin = _robust(np.concatenate([_dist(markers, "left_knee", "left_ankle"), _dist(markers, "right_knee", "right_ankle")]))
    arm = _robust(np.concatenate([_dist(markers, "left_shoulder", "left_wrist"),
                                  _dist(markers, "right_shoulder", "right_wrist")]), straight_percentile)
    mid = 0.5 * (markers[:, M["left_shoulder"]] + markers[:, M["right_shoulder"]])
    reach = _robust(np.concatenate([np.linalg.norm(mid - markers[:, M["left_knee"]], axis=-1),
                                    np.linalg.norm(mid - markers[:, M["right_knee"]], axis=-1)]), straight_percentile)
    missing = [n for n, v in (("shoulder width", sw), ("shin", shin), ("arm", arm), ("shoulder-knee", reach)) if not np.isfinite(v)]
    if missing:
        raise ProportionError(f"cannot estimate proportions: never seen: {', '.join(missing)}")
    if not 0.15 <= shin <= 1.0:
        unit = " (the markers look like millimetres: files are in metres, FORMATS.md)" if 150 <= shin <= 1000 else ""
        raise ProportionError(f"implausible body: knee-ankle distance {shin:.3g} m{unit}")
    stand = standard_pose_frames(markers, arm)
    if skin and stand.sum() >= 5:
        # skin landmarks: approximate_centres is exact only in the standard pose; a hanging arm's
        # dorsal wrist offset points outwards, not up, and the percentile arm came out ~1-2 cm long
        arm_std = _robust(np.concatenate([_dist(markers[stand], "left_shoulder", "left_wrist"),
                                          _dist(markers[stand], "right_shoulder", "right_wrist")]))
        if np.isfinite(arm_std):
            arm = arm_std
    out = db.copy()
    out[L["shoulder_width"]] = sw
    out[L["shin"]] = shin
    db_arm = db[L["upper_arm"]] + db[L["forearm"]]
    out[L["upper_arm"]] = arm * db[L["upper_arm"]] / db_arm
    out[L["forearm"]] = arm * db[L["forearm"]] / db_arm
    scale = np.exp(np.mean(np.log([sw / db[L["shoulder_width"]], shin / db[L["shin"]], arm / db_arm])))
    half_hip = 0.5 * db[L["hip_width"]] * scale
    vertical = np.sqrt(max(reach**2 - half_hip**2, (0.5 * reach) ** 2))
    db_leg = db[L["torso"]] + db[L["thigh"]]
    out[L["torso"]] = vertical * db[L["torso"]] / db_leg
    out[L["thigh"]] = vertical * db[L["thigh"]] / db_leg
    out[L["hip_width"]] = db[L["hip_width"]] * scale
    if stand.sum() >= 5:
        # legs straight below the hips: extrapolate the knee spacing past the ankle spacing;
        # skin landmarks with the legs about vertical: the Gaussian fit (with the legs apart,
        # knee and ankle spacing differing by more than LEGS_APART, the tilt dominates and the
        # extrapolation is right)
        knee_sep = _dist(markers[stand], "left_knee", "right_knee")
        ankle_sep = _dist(markers[stand], "left_ankle", "right_ankle")
        upright = np.abs(ankle_sep - knee_sep) < LEGS_APART
        if skin and upright.sum() >= 5:
            mean, cov = skin_leg_fit(_robust(knee_sep[upright]), _robust(ankle_sep[upright]),
                                     out[L["hip_width"]], out[L["thigh"]], out[L["shin"]])
            hip_sep = float(mean[0])
            if np.isfinite(hip_sep):
                offsets_out[[M["left_knee"], M["right_knee"]], 0] += mean[1]
                offsets_out[[M["left_ankle"], M["right_ankle"]], 0] += mean[2]
                leg_prior = (mean, cov)
        else:
            hip_sep = _robust(knee_sep - (ankle_sep - knee_sep) * out[L["thigh"]] / out[L["shin"]])
        if np.isfinite(hip_sep):
            out[L["hip_width"]] = float(np.clip(hip_sep, 0.6 * out[L["hip_width"]], 1.5 * out[L["hip_width"]]))
    out[L["neck"]] = db[L["neck"]] * scale
    log.debug("estimated lengths %s (scale %.3f)", np.round(out, 4), scale)
    if leg_prior is not None and out[L["hip_width"]] != leg_prior[0][0]:  # clipped: not the fit's
        leg_prior = None
    return out, offsets_out, leg_prior
