"""Subject calibration: bone lengths and marker offsets from a take (``samba-subject calibrate``).

Skin markers sit on landmarks (samba_common.markerset). The offsets and the bone lengths are
estimated together from the take itself:

1. start: the typical landmark offsets, and bone lengths from the markers moved to
   approximate joint centres (:func:`samba_server.recon.proportions.estimate_lengths`);
2. solve the take (forwards, as live) with that subject: per frame the torso rotation R_f
   and the bone directions D_f;
3. with R_f and D_f fixed, every marker is linear in the unknowns: ``m_fi = o_f + R_f (A_i(D_f)
   lengths + S_i(D_f) offset_i)`` (A: forward kinematics is linear in the lengths; S: the
   segment frame). One regularised least-squares solve over all frames (o_f eliminated per
   frame) with the typical offsets and the start lengths as Gaussian priors gives new lengths
   and offsets and their posterior standard deviations;
4. repeat 2-3 ``iterations`` times.

What the motion determines shows as a posterior sigma well below the prior's; what it does not
(e.g. the shoulder offsets in a walk, with the arms hanging) stays at the prior. A take without
the standard pose works the same way (step 1 uses percentiles over the whole take).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from samba_common.markerset import OFFSET_SIGMA, TYPICAL_OFFSETS
from samba_common.skeleton import BONE_TYPES, MARKER_NAMES, N_MARKERS
from samba_common.subject import Subject

from .db import MotionDB, load_default_db
from .proportions import ProportionError, estimate_lengths, estimate_start
from .reconstruct import Reconstructor, ReconstructConfig
from .subject_model import LENGTH_SIGMA, decorrelation, linear_update, placement_from_standard_pose

log = logging.getLogger(__name__)

@dataclass
class CalibrationReport:
    """What the calibration found: subject, frames used, rms marker residual (m) of the final
    solve, and the offsets' prior sigma (8, 3) m for comparison with the posterior."""

    subject: Subject
    frames_used: int
    residual: float
    prior_sigma: np.ndarray

    def summary(self) -> str:
        """Human summary: lengths, offsets +- sigma (mm), and which the motion determined."""
        s = self.subject
        lines = [f"frames used {self.frames_used}, rms marker residual {1000 * self.residual:.1f} mm",
                 "bone lengths (m): " + ", ".join(f"{n} {v:.3f}" for n, v in zip(BONE_TYPES, s.lengths)),
                 "marker offsets (mm, segment frame e1 e2 e3 +- 1 sigma given the solved poses; the typical "
                 "offsets' prior sigma is 8-10 mm):"]
        sig = s.offsets_sigma if s.offsets_sigma is not None else np.full((N_MARKERS, 3), np.nan)
        for n, o, e in zip(MARKER_NAMES, s.offsets, sig):
            parts = [f"{1000 * v:+6.1f} +- {1000 * u:4.1f}" for v, u in zip(o, e)]
            lines.append(f"  {n:15s} " + "  ".join(parts))
        return "\n".join(lines)


def _states(markers: np.ndarray, t: np.ndarray, db: MotionDB, cfg: ReconstructConfig, lengths: np.ndarray,
            offsets: np.ndarray, max_frames: int) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, float]:
    """Solve (a subsample of) the take forwards; returns used frame indices, R (n, 3, 3), o (n, 3),
    dirs (n, 11, 3) of the solved frames and the rms marker residual."""
    step = max(1, int(np.ceil(len(t) / max_frames)))
    rec = Reconstructor(db, cfg, lengths, offsets)
    idx, Rs, os_, ds, res = [], [], [], [], []
    for i in range(0, len(t), step):
        r = rec.solve(markers[i], float(t[i]))
        if r.status == "solved" and r.state is not None:
            idx.append(i)
            Rs.append(r.state[0])
            os_.append(r.state[1])
            ds.append(r.state[2])
            res.append(r.residual)
    if len(idx) < 10:
        raise ProportionError(f"only {len(idx)} frames could be solved: too few to calibrate the subject")
    return idx, np.array(Rs), np.array(os_), np.array(ds), float(np.sqrt(np.nanmean(np.square(res))))


def calibrate_subject(markers: np.ndarray, t: np.ndarray, db: MotionDB | None = None,
                      config: ReconstructConfig | None = None, iterations: int = 2,
                      max_frames: int = 900) -> CalibrationReport:
    """Bone lengths and skin-marker offsets of the subject in a take.

    markers: (F, 8, 3) world metres, NaN = unseen; t: (F,) seconds. iterations: solve / update
    rounds; max_frames: frames solved per round (an even subsample of longer takes).
    Raises ProportionError when the take does not show enough of the body.
    """
    db = db if db is not None else load_default_db()
    cfg = config or ReconstructConfig()
    markers = np.asarray(markers, dtype=float)
    t = np.asarray(t, dtype=float)
    lengths0, offsets0, leg_prior = estimate_start(markers, db.mean_lengths, TYPICAL_OFFSETS)
    offsets = offsets0.copy()
    lengths = lengths0.copy()
    sig_l, sig_o = LENGTH_SIGMA.copy(), OFFSET_SIGMA.copy()
    resid, used = float("nan"), 0
    for _ in range(iterations):
        idx, R, o, dirs, resid = _states(markers, t, db, cfg, lengths, offsets, max_frames)
        used = len(idx)
        lengths, offsets, sig_l, sig_o = linear_update(markers[idx], R, o, dirs, lengths0, max(resid, 0.003),
                                                       decorrelation(t[idx]), offsets0, leg_prior)
        log.debug("subject update: lengths %s offsets %s", np.round(lengths, 4), np.round(offsets, 4))
    subject = Subject(lengths, offsets, sig_o, "skin")
    return CalibrationReport(subject, used, resid, OFFSET_SIGMA.copy())


@dataclass
class PlacementGuess:
    """Where the markers of a take sit, decided from the data (``--placement auto``): placement
    "skin" or "joint_centres", the evidence ("standard pose" or "motion"), a one-line reason and
    the skin calibration if the decision made one (reuse it)."""

    placement: str
    evidence: str
    reason: str
    report: CalibrationReport | None = None  # the skin calibration when the decision needed it


#: in the motion test, joint centres are chosen when the skin model fits the markers this much worse
RESIDUAL_RATIO = 1.15


def guess_placement(markers: np.ndarray, t: np.ndarray, db: MotionDB | None = None,
                    config: ReconstructConfig | None = None) -> PlacementGuess:
    """Skin landmarks or joint centres? Both models fit the markers of ordinary motion almost
    equally well (a lateral knee/ankle offset is nearly a wider hip), so the decisive evidence is
    the standard pose: legs straight below the hips, the hip width is the knee spacing
    extrapolated past the ankles. Taken as joint centres, skin markers give hips about 10 cm too
    wide; taken as landmarks, joint-centre markers give hips about 10 cm too narrow. The
    hypothesis whose hip width is nearer the one the observed proportions (shoulder width, shin,
    arm) predict from the database wins. Without a standard pose: calibrate the skin subject and
    solve the take with zero offsets too; joint centres only when the calibrated skin model fits
    the markers clearly worse (:data:`RESIDUAL_RATIO`: varied motion shows it, a walk does not),
    else skin."""
    db = db if db is not None else load_default_db()
    cfg = config or ReconstructConfig()
    markers = np.asarray(markers, dtype=float)
    dbl = db.mean_lengths
    found = placement_from_standard_pose(markers, dbl)
    if found is not None:
        placement, reason, _n = found
        return PlacementGuess(placement, "standard pose", reason)
    report = calibrate_subject(markers, t, db, cfg)
    *_s, res_jc = _states(markers, t, db, cfg, estimate_lengths(markers, dbl), np.zeros((N_MARKERS, 3)), 900)
    res_skin = report.residual
    placement = "joint_centres" if res_skin > RESIDUAL_RATIO * res_jc else "skin"
    reason = (f"no standard pose; rms marker residual {1000 * res_jc:.2f} mm as joint centres, "
              f"{1000 * res_skin:.2f} mm as calibrated skin landmarks"
              + (" (the motion alone barely tells them apart: skin assumed)"
                 if placement == "skin" and res_jc < RESIDUAL_RATIO * res_skin else ""))
    return PlacementGuess(placement, "motion", reason, report if placement == "skin" else None)


def joint_centre_subject(markers: np.ndarray, db: MotionDB | None = None) -> Subject:
    """The subject of a take whose markers sit on the joint centres: zero offsets, lengths from
    :func:`estimate_lengths` (exactly what ``reconstruct_take`` does without a subject)."""
    db = db if db is not None else load_default_db()
    return Subject(estimate_lengths(np.asarray(markers, float), db.mean_lengths), np.zeros((N_MARKERS, 3)),
                   np.zeros((N_MARKERS, 3)), "joint_centres")


__all__ = ["CalibrationReport", "PlacementGuess", "calibrate_subject", "guess_placement", "joint_centre_subject",
           "LENGTH_SIGMA"]
