"""What is rigid for one subject, as marker distances: shin, shoulder width, arm reach.

Markers sit on joints (docs/formats.md), so the knee-ankle marker distance is the shin, the
shoulder-shoulder distance the shoulder width, and a wrist is never farther from its shoulder
than the arm (upper arm + forearm). Before the subject is measured the motion database's mean
body (else an average adult) stands in, with wider tolerances.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from samba_common.body import shoulder_height
from samba_common.skeleton import BONE_TYPES, M

__all__ = ["Body", "DEFAULT_LENGTHS", "LEVEL_M", "LS", "RS", "LW", "RW", "LK", "RK", "LA", "RA", "SIDES"]

LS, RS, LW, RW, LK, RK, LA, RA = (M[n] for n in ("left_shoulder", "right_shoulder", "left_wrist", "right_wrist",
                                                 "left_knee", "right_knee", "left_ankle", "right_ankle"))
#: (shoulder, wrist, knee, ankle) marker indices of the left and right side
SIDES = ((LS, LW, LK, LA), (RS, RW, RK, RA))
#: m: the shoulders are level within this (a wrist held at shoulder height is not a shoulder)
LEVEL_M = 0.06
#: m: identification names shoulders at most this far above their standing height, plus the
#: tolerance (jumps in the CMU clips lift them up to 0.50 m; a subject sitting or standing on a
#: climbing frame, 0.77-0.94 m, keeps the names tracking gave, but is not identified up there)
RISE_M = 0.6
#: the shoulders come closer than their standing width with both arms overhead (to 0.79 of it
#: in the CMU climbs and dances, wrists 0.3-0.5 m above their shoulders; below 0.9 of it never
#: otherwise), never much wider (1.06): with both wrists named ARMS_UP_M above their shoulders,
#: tracked names keep the shoulders down to NARROW of the width (plus the tolerance)
NARROW = 0.85
ARMS_UP_M = 0.25
_B = {n: i for i, n in enumerate(BONE_TYPES)}
#: an adult of average build (m), BONE_TYPES order, for before the subject is measured
DEFAULT_LENGTHS = np.array([0.34, 0.20, 0.50, 0.25, 0.28, 0.26, 0.44, 0.43])


@dataclass(frozen=True)
class Body:
    """Rigid marker distances of one subject with their tolerances (m).

    measured: the lengths are this subject's (tight tolerances) rather than a default body.
    """

    shin: float
    shoulder_width: float
    reach: float
    trunk: float  #: shoulder to knee of the same side, at most (torso + thigh)
    top: float  #: the highest a shoulder goes above the floor (standing height + RISE_M + tol)
    tol: float
    measured: bool
    stand: float = 0.0  #: the shoulders' height standing straight (0: not known, never scaled)

    def scaled(self, factor: float) -> "Body":
        """The same body ``factor`` times as large (lengths only; tolerances and ceiling kept)."""
        return replace(self, shin=self.shin * factor, shoulder_width=self.shoulder_width * factor,
                       reach=self.reach * factor, trunk=self.trunk * factor, stand=self.stand * factor)

    @staticmethod
    def from_lengths(lengths: np.ndarray | None, abs_tol: float = 0.05, rel_tol: float = 0.03,
                     measured: bool = True, offsets: np.ndarray | None = None) -> "Body":
        """Body from (8,) bone lengths in BONE_TYPES order, or the default body when None.
        measured=False: the lengths are a prior (e.g. the motion database's mean body), with
        the default body's wide tolerances. offsets: (8, 3) m, the subject's markers off their
        joint centres (skin markers): a wrist marker reaches at most the two offsets farther
        from its shoulder marker than the joints do."""
        measured = measured and lengths is not None
        ln = np.asarray(DEFAULT_LENGTHS if lengths is None else lengths, float)
        off = np.zeros(4) if offsets is None else np.linalg.norm(np.asarray(offsets, float)[[LS, RS, LW, RW]], axis=1)
        scale = ln[_B["shin"]] + ln[_B["thigh"]] + ln[_B["torso"]]
        tol = abs_tol + (rel_tol if measured else 0.15) * 0.5 * scale
        return Body(shin=float(ln[_B["shin"]]), shoulder_width=float(ln[_B["shoulder_width"]]),
                    reach=float(ln[_B["upper_arm"]] + ln[_B["forearm"]] + max(off[0] + off[2], off[1] + off[3])),
                    trunk=float(np.hypot(ln[_B["torso"]], 0.5 * (ln[_B["shoulder_width"]] - ln[_B["hip_width"]]))
                                + ln[_B["thigh"]]),
                    top=shoulder_height(ln) + RISE_M + float(tol),
                    tol=float(tol), measured=measured, stand=shoulder_height(ln))

    def shin_error(self, knee: np.ndarray, ankle: np.ndarray) -> float:
        return abs(float(np.linalg.norm(knee - ankle)) - self.shin)

    def width_error(self, left: np.ndarray, right: np.ndarray) -> float:
        return abs(float(np.linalg.norm(left - right)) - self.shoulder_width)

    def narrowed_error(self, left: np.ndarray, right: np.ndarray) -> float:
        """How far (m) the shoulder distance is outside [NARROW * width, width]."""
        d = float(np.linalg.norm(left - right))
        return max(d - self.shoulder_width, NARROW * self.shoulder_width - d, 0.0)

    def shin_misfit(self, markers: np.ndarray) -> float:
        """Sum over the legs with knee and ankle named in markers (8, 3) (NaN = unnamed) of how
        far (m) their distance is from the shin."""
        seen = np.isfinite(markers).all(axis=1)
        return sum(self.shin_error(markers[k], markers[a]) for _s, _w, k, a in SIDES if seen[k] and seen[a])

    def violations(self, markers: np.ndarray, narrowing: bool = False) -> list[tuple[int, ...]]:
        """Groups of labelled markers (8, 3) (NaN = unlabelled) that break a rigid distance.
        narrowing: with both arms overhead the shoulders may come closer than their width, to
        NARROW of it (for names tracked from the last frame; new names are held to the width)."""
        seen = np.isfinite(markers).all(axis=1)
        out: list[tuple[int, ...]] = []
        # only tracked names may narrow (the recovery's candidate checks call this per candidate)
        arms_up = narrowing and seen[[LS, RS, LW, RW]].all() and \
            min(markers[LW, 2] - markers[LS, 2], markers[RW, 2] - markers[RS, 2]) >= ARMS_UP_M
        width = self.narrowed_error if arms_up else self.width_error
        if seen[LS] and seen[RS] and width(markers[LS], markers[RS]) > self.tol:
            out.append((LS, RS))
        for s, w, k, a in SIDES:
            if seen[k] and seen[a] and self.shin_error(markers[k], markers[a]) > self.tol:
                out.append((k, a))
            if seen[s] and seen[w] and np.linalg.norm(markers[w] - markers[s]) > self.reach + self.tol:
                out.append((w,))
            if seen[s] and seen[k] and np.linalg.norm(markers[k] - markers[s]) > self.trunk + 2 * self.tol:
                out.append((k,))
            if seen[s] and seen[a] and np.linalg.norm(markers[a] - markers[s]) > self.trunk + self.shin + 2 * self.tol:
                out.append((a,))
        return out
