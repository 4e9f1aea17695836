"""Offline labelling from both ends of a take (``samba-process``; ``--one-pass`` turns it off).

Live, the names of a frame come from the frames before it only. Right after a blackout, or
once the subject walks back into view, they come from one identification of the 3D points
(:mod:`samba_server.labelling.identify`): a dancer's crossed legs, or a subject who turned
during the blackout, can be named the mirror way round, and tracking keeps the wrong names
until a rule catches them, up to a second later (measured on the labelling benchmark: 39 % of
the frames with a wrong or missing name were in the second after a blackout).

Offline the later frames are known too. The take is labelled a second time, backwards in time
(the same :class:`~samba_server.server.Server` code on the packets in reverse order, with the
subject the forward pass measured from its standard pose, starting from the facing the forward
pass named at the end: :func:`end_facing`), so each frame has two namings:
one tracked from the past, one from the future. The forward (live) naming stays, except:

- where the forward pass itself found a marker's name wrong within ``window_s`` (1 s) after the
  frame, or later with the two passes naming it otherwise ever since (at most ``APART_S``)
  (``LabelQuality.renamed``: a swap rule, an audit or a re-identification replaced it), the
  backward pass names that marker at the same point at the rename (within ``ALIKE_M``: the two
  passes split a merged point along their own tracks, 1-2 cm apart; tracking it, not renaming
  it itself; a rename that left the marker unnamed: where the forward pass names it next, at
  most ``NEXT_S`` later), and the backward pass did not find its own name for it wrong within
  ``window_s`` before the frame (a backward rename the forward naming confirms likewise, by
  forward names not identified or renamed within ``NEXT_S`` before: an identification after a
  blackout named a dancer's crossed ankles the wrong way round and confirmed a backward rename
  to the same wrong names 4 frames later; back only to where the forward pass last named the
  marker at the same point, as there the backward
  name was right: 4 cameras, 49 takes, seeds 3 and 11, 489 -> 469 frames not all right; the
  same cut of the forward doubt lost, 489 -> 552; the forward doubt stops only where the two
  passes named the marker alike for ``HELD_S`` (0.1 s) in a row: a single frame alike is often
  two wrong names crossing), the frame takes the backward name, and the
  backward names of the markers the forward pass left unnamed; every marker's of the renamed
  markers' half of the body (the legs; the shoulders and wrists) when the two namings agree as
  a whole at the rename (a rename of the ankles says nothing of the wrists). Where the two came
  to name a marker of that half alike at most ``JOIN_S`` before the rename, without the pass
  renaming it, it is doubted back from before that: the pass mended a swap of the whole half in
  two steps (a dancer's knees came right by tracking 3 frames before a rule renamed the ankles;
  fresh seeds, 4 cameras: 1325 -> 1299 frames not all right, no take worse on any saved set).
  The names a pass corrects were wrong for a while before the correction; a rename the backward
  pass does not confirm may itself be the mistake. Where a kept forward name and a taken
  backward one fall on one point, neither stands (the two passes dispute it); a mix that would
  still name one point twice keeps the forward names;
- never in frames whose forward names descend from the standard pose's identification (the
  take's first, clear) while the two passes have not once agreed as a whole since: a backward
  pass that came into the standard pose mirrored is the one to doubt there. A climb's forward
  pass renamed a shoulder 1.9 s in; the doubt reached back over the whole standard pose, where
  the backward pass named every marker on its mirror partner's point, and the mix left both
  shoulders unnamed for 1.8 s (001_14 seed 604: 79.5 -> 97.9 % of frames all right; no other
  take of ten saved 4-camera sets changed, 14 saved 2-camera takes 4 frames better);
- where such a mix takes only the knee or only the ankle of a leg from the backward pass,
  it takes the other too when the forward pass doubts its own name for it (even one the
  backward pass doubts as well), the backward leg keeps the subject's shin length (the median
  knee-ankle distance where the two passes name both alike) within ``SHIN_TOL_M`` and the
  mixed leg is off it by more than ``SHIN_OFF_M`` (:func:`_whole_shins`): the knee of one pass
  and the ankle of the other are no leg. A dancer's forward pass had both legs the wrong way
  round for 1 s; the backward pass, right, doubted its ankles from a rename of its own that
  the forward pass's wrong names confirmed, and the mix kept the forward ankles with the
  backward knees (005_17 seed 601: 89.1 -> 95.6 % of frames all right, 98.4 % with the split
  below; of twelve saved sets one other take mended, 16 frames fewer with a wrong name, and
  three lost a frame each);
- where both passes doubt their names of a marker (each renamed it, the forward pass after the
  frames, the backward pass before them) and name it apart, each was wrong next to its own
  rename: the stretch splits once, forward names first, backward names after, where the two
  passes' solves fit best (:func:`_split_doubts`). Two hands passing each other were swapped
  by both passes' tracking at the crossing; keeping the forward names had them wrong until the
  forward rename 0.4 s later (ten saved sets: 42 frames fewer not all right, gains on seven
  takes, 2-3 frames lost on a swordplay's wrists in four sets). With three cameras or more, as
  the fit rule below: with two, every 2-view point fits some body;
- where a forward rename gave a marker another point while the backward pass, not doubting
  it, names it at the point both passes named it through the ``AGREED_S`` before, the
  backward name holds from the rename until the two name it alike again: the forward pass's
  own past and the backward pass's future agree against the rule that renamed it (a
  climber's legs swapped by a rule for 0.6 s on another body). A marker of the rename's half
  of the body that the two named alike through the same stretch and that leaves the backward
  name within ``JOIN_S`` after the rename went with it (a rule swapped a dancer's ankles, her
  knees followed by tracking the next frame): it holds the backward name likewise, and where
  the backward pass leaves such a marker unnamed (hidden) the forward name is dropped (005_17
  on a fresh body: 92.3 -> 99.0 % of frames all right; a marker both passes leave unnamed
  while they name others counts as named alike, a blackout does not);
- where the forward pass names nothing and the backward names are not doubted so, the frame
  takes the backward names (the wait for a clear identification after a blackout);
- where the forward pass leaves a marker unnamed (a hand hidden from a view, a point the
  points stage did not make) and the backward pass, not doubting it, names it without a break
  from an edge of that gap where both passes name it at the same point, the backward name
  fills the gap: there both followed the same marker;
- where the two namings differ in the shoulders, the forward names descend from a coin-flip
  identification (margin < ``COIN_M``; never the take's first, from the standard pose) and the backward ones
  from a clear one (>= ``CLEAR_M``), the frame takes the backward names if they name as many
  markers, or at least 4. After a blackout the forward pass may identify a subject whose mirror
  image scores the same (swordplay on another body was named all left for right for the last
  3.3 s of the take) and no rule renames it; the backward pass reached those frames tracking
  from a clear identification at the end of the take. Frames after the two passes agreed as
  a whole no longer descend from the coin flip (it was settled; a later difference is a slip
  of one pass); frames after an identification that renamed neither shoulder while the pass
  held names (an audit moving a wrist, which counts agreeing with the tracked names as
  evidence) still do (swordplay on another body kept the mirror names for the last 0.4 s after
  such an audit). Not where the two name the shoulders alike: the rule is for the mirror image,
  and a dancer standing with her legs crossed at the take's end was identified clearly but
  uncrossed by the backward pass, while the coin flip after the blackout had named her right
  (005_11 seed 83 through the README's commands: the legs swapped for the last 1.5 s; no
  take of the benchmark's saved passes changed). (Tried: the clearer identification
  winning wherever the two differ, by 0.1 m: -1.0 point on the benchmark, whose backward
  passes often go wrong after a clear identification.)
- where the forward pass names a wrist on the point the backward pass names as a shoulder the
  forward pass leaves unnamed, that shoulder takes its backward name and the wrist is unnamed:
  a hand at the other shoulder takes the shoulder's point (the two markers on one 3D point)
  and the shoulder goes unnamed; a shoulder is seldom hidden from every view for long, a hand
  often is (a dribble on another body: a left wrist on the right shoulder's point for 0.5 s).

- where the forward pass names a marker on a point the backward pass names as another marker,
  which the forward pass leaves unnamed, the forward pass named it again from a stale prediction
  after a gap (it was unnamed the frame before) and the backward pass came into those frames
  tracking the other marker (it names it the frame after), the backward names of both stand:
  one pass guessed, the other tracked (the high rig's climb: both shoulders hidden for 20
  frames, then the right one named left by the forward pass for 1.2 s). With three cameras or
  more: with two, names are picked up after gaps all the time in both passes.

- where the chosen shoulders are the backward pass's the other way round in a run that starts
  at most ``PARTED_S`` after the forward pass lost a shoulder while naming other markers, and
  the backward names there descend from a clear identification, the backward shoulders and
  wrists, and the backward legs where the forward ones are their mirror (named against the
  facing of those shoulders): each pass is right going into the gap and guesses coming out
  (:func:`_guessed_shoulders`; a climber's shoulders lost under the raised arms for 3 frames,
  picked up mirrored, and the whole body kept so for 4.2 s, 001_14 on a fresh body, 54.2 ->
  97.4 % of frames all right; the mixed-height rig's 005_14, 76.2 -> 84.5 %; no saved take
  worse). With three cameras or more.

- where, for at most ``COURSE_S`` (1/3 s), the name chosen so far leaves the backward one
  between two frames where both name the marker at the same point, the backward name is taken
  in each frame it lies nearer the straight line between those two points (within
  ``COURSE_M``, 10 cm, of it, on a point no other chosen name holds): the forward pass slipped
  onto another marker's point, or dropped the name, for a few frames, and the marker's course
  on both sides says which name continued it (4 cameras, 49 takes, seeds 3 and 11: 469 -> 451
  frames not all right; of six other sets of saved passes, two rigs and older labellers,
  five lost 11-23 frames each and one gained 1). Not a backward name its pass says no view
  saw apart from its partner (``PassResult.unseparated``: hands together on a sword hilt,
  5-10 cm apart, where the course cannot tell them; 002_07 on a fresh body, 90.1 -> 93.2 %).

- last, where the two passes name markers at points apart over a run of frames and the
  backward names fit the solver ``FIT_RATIO`` (2) times better than the forward ones, and by
  ``FIT_GAIN_M2`` (:func:`_misfit`: each pass's own solve residuals, a marker left unnamed
  counting as one ``FIT_UNNAMED_M`` off), the run takes the backward names: the
  reconstruction's fit judges two namings no rule told apart (a dribbler's knee named on the
  other knee's point for 2 s, 5-19 mm against 0.4-2.4 mm; a climber's shoulder and wrists
  confused for 2 s). Only where the backward names fit well (rms within ``FIT_GOOD_M``, 7 mm):
  the better of two bad fits is no verdict (the database fits an uncrossed naming of crossed
  feet better than the truth). On saved passes of bodies no rule was traced on (4 cameras, the
  49 clips on seeds 501-503 with the blackout anywhere in the motion and on 501 with it
  mid-motion: 196 takes) frames not all right 2241 -> 1928; seeds 3 and 11, which the rules
  were traced on, 426 -> 435; the high and the mixed-height rigs (seed 3) 1025 -> 686 and 815
  -> 775 (judged per run since the twenty-fifth session, frames where the passes differ only
  in a marker one leaves unnamed ending a run: with the halves rule above 1928 -> 1879, 435 ->
  425, 1461 -> 1424 both rigs). Not the other way round (forward names fitting better
  replacing backward names a rule took): about 50 frames fewer not all right, but 26 more
  with a wrong name. With three cameras or more: with two, every 2-view point fits some body
  (14 takes: 1116 -> 1161).

Otherwise a naming that neither pass corrected is not overruled by the other: the backward
pass starts mid-motion at the end of the take, with no standard pose, and its first
identification is often the weaker one (tried: preferring the pass that had tracked longer
lost 17 points on a take whose backward identification named the legs the wrong way round).
The chosen markers are then solved forwards by a new solver built as the live one and
backwards by one for the subject it measured, the two merged per frame
(:func:`~samba_server.recon.reconstruct.solve_both_ways`). Each joint's bound is raised to
at least how far apart the two passes put its marker (:func:`disputed_m`; the joints placed
from it with it): whichever naming was chosen, a marker the passes named at points 30 cm apart
may be 30 cm off.

The recording (``--record``) keeps the live, forward-only poses: ``samba-replay`` of it
equals it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from samba_common.skeleton import N_MARKERS

from .labelling import bit_markers, marker_bits
from .labelling.labeller import facing_of
from .labelling.rigid import LA, LK, LS, LW, RA, RK, RS, RW, SIDES
from .recon.bounds import mirrored_legs, mirrored_pairs, mirrored_wrists, widened
from .recon.reconstruct import solve_both_ways
from .server import Server, ServerConfig

log = logging.getLogger(__name__)

#: bit sets of the two halves of the body a rename confirmed as a whole speaks for
_UPPER = (1 << LS) | (1 << RS) | (1 << LW) | (1 << RW)
_LEGS = (1 << LK) | (1 << RK) | (1 << LA) | (1 << RA)

__all__ = ["PassResult", "backward_pass", "choose", "disputed_m", "end_facing", "legs_unsure_of", "loose_of",
           "relabel_both_ways", "unseparated_of"]

#: m (LabelQuality.margin_m, 0.1 m per identification score unit): an identification whose
#: best labelling beat the runner-up by less than this was a coin flip (after a blackout the
#: mirror image of a subject can score the same) ...
COIN_M = 0.01
#: ... and one by this much (the labelling's ``min_margin``: taken at once) was clear
CLEAR_M = 0.06
#: m: the margin the standard pose's identification counts as (a take's first: never a coin flip)
STANDARD_POSE_M = 1e9
#: s: a rename that left a marker unnamed is checked where the forward pass names it next,
#: at most this much later
NEXT_S = 0.1
#: s: a forward rename is refuted only where both passes named the marker alike this long
#: before it
AGREED_S = 0.5
#: s: a confirmed forward rename also doubts the names before it back to where the two passes
#: last named the marker alike, at most this long (on the harness's takes 3 s and no bound
#: gave the same)
APART_S = 3.0
#: s: ... and for a marker of a rename's half of the body the pass did not rename, from before
#: an agreement of the two passes at most this long right before the rename
JOIN_S = 0.1
#: s: a forward rename doubts the names before it back to where the two passes named the marker
#: at the same point for at least this long
HELD_S = 0.1
#: s: a stretch where the chosen name of a marker leaves the backward one, between frames where
#: the two name it at the same point, is checked against the marker's course if at most this long
COURSE_S = 1.0 / 3.0
#: m: ... and the backward name taken only this near the course
COURSE_M = 0.1
#: s: the backward pass's first identification assumes the facing the forward pass named this
#: near the take's end
END_FACING_S = 0.5
#: m: a marker a pass leaves unnamed costs as much in its fit as a named one this far off ...
FIT_UNNAMED_M = 0.01
#: ... and a named one costs at most as much as one this far off (a pass's solve right after a
#: rename, or of a marker on a merged point, can be off by more with the right names)
FIT_CAP_M = 0.02
#: m: a stretch where the two passes differ takes the backward names only where they fit a body
#: this well (rms over the stretch's frames and markers) ...
FIT_GOOD_M = 0.007
#: ... and this many times better than the forward ones ...
FIT_RATIO = 2.0
#: ... and by this much (m^2, summed over the stretch's frames and markers: 0.003 is 30
#: marker-frames left unnamed)
FIT_GAIN_M2 = 0.003
#: m: a pass names a leg marker as chosen when its marker is this near the chosen one
ALIKE_M = 0.03
#: m: hands whose wrists either pass names this near each other are together ...
TOGETHER_M = 0.10
#: ... and this far apart, apart (between the two: neither; two hands on a sword's hilt stay
#: 13-17 cm apart: at 15 cm a swordplay's wrists, swapped by the forward pass for 0.6 s, were
#: never apart, 002_07 seed 617)
APART_M = 0.13
#: s: the wrists the two passes name the other way round take the backward names where the
#: hands were together at most this long before and not apart ... after
PARTED_S = 0.5
#: m: a leg named by one pass keeps the subject's shin length within this ...
SHIN_TOL_M = 0.03
#: ... and a leg of one pass's knee and the other's ankle is no leg when off it by more than this
SHIN_OFF_M = 0.06


@dataclass
class PassResult:
    """One labelling pass over F frames. markers: (F, 8, 3) world m (NaN = not named);
    renamed: (F,) int, bit m set where the pass found marker m's name, held until the frame
    before, wrong and replaced it (``LabelQuality.renamed``); margin: (F,) label margin m;
    identified: (F,) the margin (m, ``LabelQuality.margin_m``) of the identification that
    named the frame, NaN on the frames tracking named (None: no identification known); loose:
    (F, 8) bool, the named markers whose position is rough (:meth:`Labeller.loose`; None: none);
    residual: (F,) m, the pass's own solve of its names (rms marker fit; NaN unsolved; None:
    not known); legs_unsure: (F,) bool, frames whose leg names may be each other's
    (:attr:`Labeller.legs_unsure`; None: not known); unseparated: (F, 8) bool, the named wrists
    no view saw apart (:meth:`Labeller.unseparated`; None: none)."""

    markers: np.ndarray
    renamed: np.ndarray
    margin: np.ndarray
    identified: np.ndarray | None = None
    loose: np.ndarray | None = None
    residual: np.ndarray | None = None
    legs_unsure: np.ndarray | None = None
    unseparated: np.ndarray | None = None


def _standard_pose_clear(identified: np.ndarray | None) -> np.ndarray | None:
    """A copy of a forward pass's identification margins (F,) (NaN elsewhere) with its first
    one, the standard pose's, set to ``STANDARD_POSE_M``: never a coin flip, and its lineage
    (:func:`_lineage`) tells the frames that descend from it. None stays None."""
    if identified is None:
        return None
    out = identified.copy()
    first = np.flatnonzero(np.isfinite(out))
    if first.size:
        out[first[0]] = STANDARD_POSE_M
    return out


def end_facing(fwd: PassResult, t: np.ndarray, within_s: float = END_FACING_S) -> np.ndarray | None:
    """(2,) unit horizontal facing of the subject at the take's end as the forward pass named
    it: its shoulders in the last frame within ``within_s`` of the end that names both, when
    those names do not descend from a coin-flip identification (margin < ``COIN_M``; the
    standard pose's is none) and the pass renamed no shoulder in the take's last second (a
    shoulder lost and picked up on the other one's point left a dribble's live facing reversed
    at its end, and a rule renamed it: on the mixed-height rig the backward pass started
    mirrored from it, 81.8 -> 75.6 %). None otherwise (or without identification margins)."""
    if fwd.identified is None or not np.isfinite(fwd.identified).any():
        return None
    if bit_markers(fwd.renamed[t >= t[-1] - 1.0].astype(np.int64))[:, [LS, RS]].any():
        return None
    named = np.isfinite(fwd.markers).all(axis=2)
    lineage = _lineage(_standard_pose_clear(fwd.identified), named.any(axis=1), forward=True, renamed=fwd.renamed)
    for k in range(len(t) - 1, -1, -1):
        if float(t[-1] - t[k]) > within_s:
            break
        if named[k, [LS, RS]].all():
            coin_flip = bool(lineage[k] < COIN_M)
            return None if coin_flip else facing_of(fwd.markers[k, LS], fwd.markers[k, RS])
    return None


def backward_pass(server: Server, packets: list[list], t: np.ndarray, progress=None,
                  facing: np.ndarray | None = None) -> PassResult | None:
    """Label the frames again from the last to the first with a twin of ``server`` (same rig,
    labelling and triangulation configuration, solver built for the subject ``server``
    measured). packets: per frame (F) a list per rig camera of MarkerPacket or None; t: (F,)
    s; progress: optional, updated once per frame; facing: (2,) the subject's facing at the
    take's end (:func:`end_facing`) for the first identification, else the standard pose's.
    None when the forward pass measured no subject (never identified)."""
    rec = server.reconstructor
    subject = getattr(server, "subject", None)
    if rec is None or subject is None or not hasattr(rec, "again"):
        return None
    label_config = replace(server.labeller.config, time_reversed=True)
    if facing is not None:
        label_config = replace(label_config, first_facing=(float(facing[0]), float(facing[1])))
    twin = Server(server.rig, None, rec.again(subject), ServerConfig(max_lag_ms=0.0, keep_history=False),
                  tri_config=server.triangulator.config, label_config=label_config)
    F = len(t)
    if F:
        # the reflections the forward pass learnt are there from the backward pass's first frame
        twin.labeller.still.seed(server.labeller.still.static(float(t[-1])), 0.0)
    out = PassResult(np.full((F, N_MARKERS, 3), np.nan), np.zeros(F, np.int64), np.full(F, np.nan),
                     np.full(F, np.nan), np.zeros((F, N_MARKERS), bool), np.full(F, np.nan), np.zeros(F, bool),
                     np.zeros((F, N_MARKERS), bool))
    t_end = float(t[-1]) if F else 0.0
    for k in range(F - 1, -1, -1):
        tb = t_end - float(t[k])  # backwards time runs forwards
        markers, _mask, q = twin.label_packets(packets[k], tb)
        markers, _joints, out.residual[k], _bounds = twin.solve_markers(markers, tb)
        out.markers[k], out.margin[k], out.renamed[k] = markers, q.margin_m, q.renamed
        out.loose[k] = twin.labeller.loose(markers)
        out.unseparated[k] = twin.labeller.unseparated(markers)
        out.legs_unsure[k] = twin.labeller.legs_unsure
        if q.mode == "identified":
            out.identified[k] = q.margin_m
        if progress is not None:
            progress.update(1)
    server.stats.label_errors += twin.stats.label_errors
    return out


def _doubted(renamed: np.ndarray, named: np.ndarray, t: np.ndarray, window_s: float, forward: bool,
             confirmed: np.ndarray | None = None, own: np.ndarray | None = None) -> np.ndarray:
    """(F,) int, bit m set on the frames whose name for marker m the pass itself replaced as
    wrong within window_s s later in its own direction of travel (forward: later frames;
    backward: earlier ones), with some name in every frame between (a pass that lost every
    name has none to correct), and, with confirmed ((F, 8) bool: the other pass names marker m
    at the same point), no frame between where the other pass confirms the name (the name
    the rename replaced went wrong after that frame, not before), and, with own ((F,) int bits:
    every rename of the pass, ``renamed`` being those the other pass confirms), no rename of
    that marker between that the other pass does not confirm (the names before it are not the
    ones the later rename replaced: a dancer's forward pass named the legs right for 1 s,
    renamed them wrongly, and back 5 frames later; doubted back past the wrong rename, the 1 s
    took the backward pass's legs, which were the other way round: 005_05 on a fresh body,
    86.1 -> 95.7 % of frames all right). renamed: (F,) int bits; named: (F,) bool; t: (F,) s."""
    F = len(t)
    out = np.zeros(F, np.int64)
    t_fix = np.full(N_MARKERS, np.nan)  # per marker: when the pass last renamed it
    order = range(F - 1, -1, -1) if forward else range(F)  # walk against the pass's direction
    for k in order:
        if not named[k]:
            t_fix[:] = np.nan
            continue
        live = np.abs(t_fix - t[k]) <= window_s
        out[k] = marker_bits(live)
        if confirmed is not None:
            t_fix[confirmed[k]] = np.nan
        if own is not None:
            # a rename of its own that the other pass does not confirm: the names before it
            # are not the ones a later rename replaced
            t_fix[bit_markers(int(own[k]) & ~int(renamed[k]))] = np.nan
        t_fix[bit_markers(renamed[k])] = t[k]
    return out


def _apart_before(renamed: np.ndarray, same: np.ndarray, t: np.ndarray, own: np.ndarray | None = None,
                  max_s: float = APART_S, join_s: float = JOIN_S) -> np.ndarray:
    """(F,) int, bit m set on the frames before a rename of marker m (renamed: (F,) int bits)
    back to where the two passes last named m alike (same: (F, 8) bool), at most max_s s
    before it: the stretch the renamed name had been wrong, however long (a climber's wrist
    named on the other shoulder's point for 1.9 s before a rule gave the point back). A marker
    of the rename's half of the body the pass did not rename itself (own: (F,) int bits, the
    pass's ``renamed``) that the two came to name alike at most join_s s before the rename
    walks back from before that: the pass mended a swap of the whole half in two steps, the
    tracking one marker, a rule the rest (a dancer's knees came right by themselves 3 frames
    before a rule renamed the ankles, the legs swapped for 1.3 s before)."""
    out = np.zeros(len(t), np.int64)
    for k, m in zip(*np.nonzero(bit_markers(renamed))):
        j = k - 1
        if own is not None and not (int(own[k]) >> m) & 1:
            i = j
            while i >= 0 and same[i, m] and t[k] - t[i] <= join_s:
                i -= 1
            if i >= 0 and t[k] - t[i] <= join_s:
                j = i
        while j >= 0 and not same[j, m] and t[k] - t[j] <= max_s:
            out[j] |= 1 << m
            j -= 1
    return out


def _held(mask: np.ndarray, t: np.ndarray, min_s: float, cut: np.ndarray) -> np.ndarray:
    """(F, M) bool: mask (F, M) where it holds for at least min_s s in a row (t: (F,) s), a row
    ending before each frame where cut (F, M) is set (a rename: the agreement before it is not
    the one after it)."""
    out = np.zeros_like(mask)
    for m in range(mask.shape[1]):
        for a, b in _runs(mask[:, m]):
            for a2, b2 in _pieces(a, b, cut[:, m]):
                if t[b2 - 1] - t[a2] >= min_s - 1e-9:
                    out[a2:b2, m] = True
    return out


def _renamed_soon(renamed: np.ndarray, t: np.ndarray, within_s: float, forward: bool = False) -> np.ndarray:
    """(F,) int bits: per frame k the markers renamed (renamed (F,) int bits) in some frame j
    with t[k] <= t[j] <= t[k] + within_s (forward: t[k] - within_s <= t[j] <= t[k]): the
    renames a pass's names at k descend from, made a few frames before in its travel. t: (F,) s."""
    out = renamed.copy()
    for j in np.flatnonzero(renamed):
        if forward:
            out[j + 1:np.searchsorted(t, t[j] + within_s + 1e-9)] |= renamed[j]
        else:
            out[np.searchsorted(t, t[j] - within_s - 1e-9):j] |= renamed[j]
    return out


def _lineage(identified: np.ndarray | None, named: np.ndarray, forward: bool,
             settled: np.ndarray | None = None, renamed: np.ndarray | None = None) -> np.ndarray:
    """(F,) the margin (m) of the identification each frame's names descend from in the pass's
    direction of travel (forward: the last one before or at the frame; backward: after or at
    it), NaN where the pass named nothing since, or a settled frame (not an identification's)
    came since (or none is known). An identification that renamed neither shoulder while the
    pass held names (an audit that moved a wrist: it counts agreeing with the tracked names as
    evidence, so its margin says nothing about the facing) does not start a lineage: the frames
    after it descend from the less clear of it and the one before. identified: (F,) margins of
    the identification frames, NaN elsewhere; named, settled: (F,) bool; renamed: (F,) int
    bits (``LabelQuality.renamed``)."""
    F = len(named)
    out = np.full(F, np.nan)
    if identified is None:
        return out
    kept = np.zeros(F, bool) if renamed is None else (bit_markers(renamed)[:, [LS, RS]] == 0).all(axis=1)
    cur = np.nan
    for k in (range(F) if forward else range(F - 1, -1, -1)):
        if not named[k]:
            cur = np.nan
        elif np.isfinite(identified[k]):
            cur = min(cur, float(identified[k])) if kept[k] and np.isfinite(cur) else float(identified[k])
        elif settled is not None and settled[k]:
            cur = np.nan
        out[k] = cur
    return out


def _renamed_to_none(renamed: np.ndarray, nf: np.ndarray, nb: np.ndarray, alike: np.ndarray,
                     t: np.ndarray, within_s: float = NEXT_S) -> np.ndarray:
    """(F, 8) bool: markers a forward rename left unnamed (the pass found the name wrong and
    had no other point for it yet) that the backward pass names there, and that the forward
    pass names again within ``within_s`` s, before any other rename of them, at the backward
    pass's point. renamed: (F,) int bits; nf, nb: (F, 8) the forward, backward pass names the
    marker; alike: (F, 8) both name it at the same point; t: (F,) s."""
    out = np.zeros_like(nf)
    bits = bit_markers(renamed)
    for k, m in zip(*np.nonzero(bits & ~nf & nb)):
        for j in range(k + 1, len(t)):
            if t[j] - t[k] > within_s or bits[j, m]:
                break
            if nf[j, m]:
                out[k, m] = alike[j, m]
                break
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in mask (F,) bool, stop exclusive."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _pieces(a: int, b: int, cut: np.ndarray) -> list[tuple[int, int]]:
    """The frames [a, b) split before each frame k (a < k < b) where cut (>= b,) bool is set:
    (start, stop) of each piece, stop exclusive."""
    edges = [a, *(a + 1 + np.flatnonzero(cut[a + 1:b])).tolist(), b]
    return list(zip(edges[:-1], edges[1:]))


def _bridged(nf: np.ndarray, nb: np.ndarray, alike: np.ndarray, lead: np.ndarray) -> np.ndarray:
    """(F, 8) bool: the frames of each gap in the forward pass's names of a marker (a hand
    hidden from a view, a point the points stage did not make) that the backward pass names
    without a break from an edge of the gap where both passes name the marker at the same
    point: there both followed the same marker, so the backward name across the gap is its
    continuation. A lead frame (the forward pass names nothing, the backward names are
    taken: the first frames after a blackout) is such an edge for each marker the backward
    pass names there, not part of a gap: the forward pass, picking the subject up a few
    markers at a time, leaves the rest unnamed that the backward pass named on from there (a
    dribbler's right wrist after the blackout, 0.2 s). nf, nb: (F, 8) the forward, backward
    pass names the marker; alike: (F, 8) both name it at the same point; lead: (F,) bool."""
    F = len(nf)
    out = np.zeros_like(nf)
    alike = alike | (lead[:, None] & nb)
    for m in range(nf.shape[1]):
        for a, b in _runs(~nf[:, m] & ~lead):  # the gaps
            if a > 0 and alike[a - 1, m]:
                run = np.flatnonzero(~nb[a:b, m])
                out[a:a + (run[0] if run.size else b - a), m] = True
            if b < F and alike[b, m]:
                run = np.flatnonzero(~nb[a:b, m][::-1])
                out[b - (run[0] if run.size else b - a):b, m] = True
    return out


def _refuted(renamed: np.ndarray, nf: np.ndarray, nb: np.ndarray, alike: np.ndarray, t: np.ndarray,
             agreed_s: float = AGREED_S, join_s: float = JOIN_S) -> np.ndarray:
    """(F, 8) bool: the frames from a forward rename on, until the two passes name the
    marker alike again (or the forward pass renames it again, or neither names it), of each
    marker the rename gave another point to where the backward pass, reaching the rename
    tracking, names it at the point both passes named it in every frame of the ``agreed_s`` s
    before: the forward pass's own past and the backward pass's future agree against the rule
    that renamed it. Likewise from the first frame it leaves the backward name, for each marker
    of the rename's half of the body (the legs; the shoulders and wrists) the rename did not
    rename, named alike through the same ``agreed_s``, that does so within ``join_s`` after
    the rename: it went with the rename (a dancer's knees, tracked onto each other's points
    the frame after a rule swapped her ankles). Where the backward pass leaves the marker
    unnamed, the frame is marked too: the forward name is wrong there as well.
    Not after a shorter agreement: right after a blackout both passes can name a subject the
    same wrong way (two cameras, a dancer's legs named the mirror way round by the forward
    identification and the backward tracking alike), and the rename mends that. renamed: (F,)
    int bits; nf, nb: (F, 8) the forward, backward pass names the marker; alike: (F, 8) the two
    name it alike (at the same point, or neither while both name other markers); t: (F,) s."""
    F = len(nf)
    out = np.zeros_like(nf)
    bits = bit_markers(renamed)

    def hold(k: int, m: int) -> None:  # the backward name from frame k until the two agree again
        j = k
        while j < F and (nb[j, m] or nf[j, m]) and not alike[j, m] and not (j > k and bits[j, m]):
            j += 1
        out[k:j, m] = True

    for k, m in zip(*np.nonzero(bits)):
        before = np.flatnonzero(t[:k] >= t[k] - agreed_s)
        if t[0] > t[k] - agreed_s or not alike[before, m].all() or alike[k, m] or not (nf[k, m] and nb[k, m]):
            continue
        hold(k, m)
        for n in np.flatnonzero(bit_markers(int(_halves(1 << int(m)))) & ~bits[k]):
            j = k
            while j < F and alike[j, n] and t[j] - t[k] <= join_s:
                j += 1
            if alike[before, n].all() and j < F and t[j] - t[k] <= join_s and nf[j, n] and not bits[j, n]:
                hold(j, n)
    return out


def _picked_up(fwd: np.ndarray, bwd: np.ndarray) -> list[tuple[int, int, int, int]]:
    """(a, b, k0, k1): the runs of frames k0..k1 where the forward names fwd (F, 8, 3) put marker a
    within 1 cm of the backward names bwd's (F, 8, 3) marker b and leave b unnamed, when the
    forward pass had a unnamed in the frame before the run (it named a again from a stale
    prediction after a gap) and the backward pass names b in the frame after it (it came into
    the run tracking b). Runs at either end of the take are left out."""
    nf, nb = np.isfinite(fwd).all(axis=2), np.isfinite(bwd).all(axis=2)
    F, out = len(fwd), []
    for a in range(N_MARKERS):
        for b in range(N_MARKERS):
            if a == b:
                continue
            for k0, stop in _runs(nf[:, a] & ~nf[:, b] & _within(fwd[:, a], bwd[:, b])):
                k1 = stop - 1
                if 0 < k0 and k1 < F - 1 and not nf[k0 - 1, a] and nb[k1 + 1, b]:
                    out.append((a, b, k0, k1))
    return out


def _within(a: np.ndarray, b: np.ndarray, tol: float = 0.01) -> np.ndarray:
    """(...) bool: points a (..., 3) and b (..., 3) (broadcast; NaN = unnamed), both named,
    within tol (m) of each other."""
    return np.linalg.norm(np.nan_to_num(a - b, nan=1.0), axis=-1) <= tol


def _on_course(markers: np.ndarray, bwd: np.ndarray, t: np.ndarray, max_s: float = COURSE_S,
               gate_m: float = COURSE_M, unsure: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The chosen names markers (F, 8, 3) with the backward names bwd (F, 8, 3) taken where a
    marker's course says so: in a stretch of at most max_s s where the chosen name of the
    marker leaves the backward one (the forward pass's slip onto another marker's point, or a
    name it dropped) between two frames where both name it at the same point, each frame takes
    the backward name when it lies nearer the straight course between those two points than
    the chosen name (or the chosen name is none) and within gate_m of it, and no other chosen
    name holds its point. Not a backward name its pass says no view saw apart from its partner
    (unsure (F, 8) bool, ``PassResult.unseparated``: hands together on a hilt, 5-10 cm apart,
    where the course cannot tell them; a swordplay's left wrist took the right one's point for
    0.3 s, 002_07 on a fresh body). Returns a new (F, 8, 3) array and (F,) bool: frames changed."""
    out = markers.copy()
    changed = np.zeros(len(t), bool)
    alike = _within(markers, bwd)  # (F, 8)
    nb = np.isfinite(bwd).all(axis=2)
    for m in range(markers.shape[1]):
        edges = np.flatnonzero(np.diff(alike[:, m].astype(np.int8)))  # last alike, last apart frames
        for a, b in zip(edges[:-1], edges[1:]):
            if not alike[a, m] or b + 1 >= len(t) or t[b + 1] - t[a] > max_s + 1e-9 or not nb[a + 1:b + 1, m].all():
                continue
            for k in range(a + 1, b + 1):
                if unsure is not None and unsure[k, m]:
                    continue
                w = (t[k] - t[a]) / (t[b + 1] - t[a])
                course = (1.0 - w) * markers[a, m] + w * markers[b + 1, m]
                d_b = float(np.linalg.norm(bwd[k, m] - course))
                d_c = float(np.linalg.norm(out[k, m] - course)) if np.isfinite(out[k, m]).all() else np.inf
                if d_b < d_c and d_b <= gate_m and not _within(np.delete(out[k], m, axis=0), bwd[k, m]).any():
                    out[k, m], changed[k] = bwd[k, m], True
    return out, changed


def _on_one_point(markers: np.ndarray) -> np.ndarray:
    """(8, 8) bool: pairs of named markers (8, 3) (NaN = unnamed) within 1 cm of each other
    (the diagonal is True for the named ones)."""
    return _within(markers[:, None], markers[None])


def _disputed(mixed: np.ndarray, take: np.ndarray) -> np.ndarray:
    """(8,) bool: the markers of a mixed naming mixed (8, 3) (take (8,) bool: the names
    taken from the backward pass) on a point within 1 cm of a marker of the other pass: the
    two passes name that point as different markers, so neither name stands."""
    return (_on_one_point(mixed) & (take[:, None] != take[None])).any(axis=1)


def _wrist_on_shoulder(fwd: np.ndarray, bwd: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """(wrist, shoulder, (F,) bool) for each wrist and shoulder: the frames where the forward
    names fwd (F, 8, 3) put the wrist within 1 cm of the backward names bwd's (F, 8, 3)
    shoulder and leave that shoulder unnamed."""
    return [(w, s, _within(fwd[:, w], bwd[:, s]) & ~np.isfinite(fwd[:, s]).all(axis=1))
            for w in (LW, RW) for s in (LS, RS)]


def _shoulder_kept(markers: np.ndarray, fwd: np.ndarray, bwd: np.ndarray) -> None:
    """Where the backward names bwd (F, 8, 3) put a wrist on the forward names fwd's (F, 8, 3)
    shoulder and leave that shoulder unnamed, and the chosen names markers (F, 8, 3) took the
    backward pass's view (that wrist there, or the shoulder not named where the forward pass
    names it), give the shoulder and the wrist their forward names again, in place (unless that
    names one point twice more often, or the forward pass's other shoulder is on a point the
    backward pass names as another marker: a climber's every marker named one place on by the
    forward pass for 0.4 s, and the rule put back two of those wrong names, 001_14 on a fresh
    body). A shoulder barely moves on the body; a wrist on a shoulder's point is a hand lost at
    the shoulder: on the saved passes of seeds 3, 601, 602 and 606, in the 112 frames where the
    backward pass named a wrist so, the forward pass's shoulder was right in 108 and the
    backward wrist in none (005_03 seed 606: the backward pass named the left wrist on the
    right shoulder for 0.4 s, the choice took it). The other way round is
    :func:`_wrist_on_shoulder`."""
    for w, s, hit in _wrist_on_shoulder(bwd, fwd):
        hit &= _within(markers[:, w], bwd[:, w]) | ~_within(markers[:, s], fwd[:, s])
        other = RS if s == LS else LS
        # not where the forward pass's other shoulder is on a point the backward pass names as
        # another marker: its upper body is named one place on, not a hand lost at a shoulder
        hit &= ~_within(fwd[:, other, None], np.delete(bwd, other, axis=1)).any(axis=1)
        for k in np.flatnonzero(hit):
            _take_undoubled(markers, k, [w, s], fwd[k, [w, s]])


def _misfits(p: PassResult, frames: np.ndarray) -> np.ndarray:
    """(len(frames),) m^2: how badly pass p's names fit its own solves in each of frames
    (indices): per marker, a named one its frame's rms residual squared (at most
    ``FIT_CAP_M`` squared), an unnamed one ``FIT_UNNAMED_M`` squared, summed."""
    n = np.isfinite(p.markers[frames]).all(axis=2).sum(axis=1)
    r = np.minimum(p.residual[frames], FIT_CAP_M)
    return n * np.nan_to_num(r) ** 2 + (N_MARKERS - n) * FIT_UNNAMED_M**2


def _misfit(p: PassResult, frames: np.ndarray) -> float:
    """How badly pass p's names fit its own solves over frames (indices) (m^2): the sum of
    :func:`_misfits`."""
    return float(_misfits(p, frames).sum())


def _fits_better(fwd: PassResult, bwd: PassResult, nf: np.ndarray, nb: np.ndarray,
                 both: np.ndarray) -> np.ndarray:
    """(F,) bool: the frames of each run where the two passes name some marker at points more
    than 1 cm apart (in each frame) whose backward names fit the solver well (rms within
    ``FIT_GOOD_M``) and by ``FIT_RATIO`` times and ``FIT_GAIN_M2`` better than the forward
    ones (:func:`_misfit`, over the frames where each pass that names a marker has a
    residual: a solver still measuring the subject judged nothing): the reconstruction's fit
    as the judge of two namings no rule told apart. Where neither naming fits a body well, the
    better of two bad fits is no verdict: the database fits an uncrossed naming of crossed feet
    better than the truth (a dance on the mixed-height rig: 99.2 -> 58.9 % of frames all right
    without that bound).
    Frames where the two differ only in markers one of them leaves unnamed are not judged and
    end a run: the wrists named the wrong way round by the backward pass, then alike but for a
    hidden hand, then the forward pass's wrists wrong, are two verdicts, not one that gave the
    backward names to both (002_09 on a fresh body). Within a run that takes the backward
    names, a stretch between two renames of either pass (where its names change) whose
    forward names fit clearly better (the same test the other way round) keeps them. A
    swordplay's forward pass had the legs the wrong way round for 1 s until its knees' hold
    swapped them, the backward pass from the take's end for 1.2 s until its own did, the two
    stretches touching: judged as one run the backward names fitted better and were taken
    for both, the legs wrong for the last 1.2 s (002_07 seed 601, 71.1 -> 79.8 % of frames all
    right with the stretches apart). Judging the stretches apart both ways (a stretch whose
    backward names fit clearly better taking them in a run that does not) also mended a climb
    on the high rig (001_14 seed 3, 70.2 -> 80.8 %) but lost 15 frames on four other takes, 9
    of them on a seed never used before (002_10 seed 604). nf, nb: (F, 8) bool, the forward,
    backward pass names marker m; both: (F, 8) bool, the two name it at the same point. False
    everywhere when a pass has no residuals."""
    F = len(fwd.markers)
    out = np.zeros(F, bool)
    if fwd.residual is None or bwd.residual is None:
        return out
    judged = (np.isfinite(fwd.residual) | ~nf.any(axis=1)) & (np.isfinite(bwd.residual) | ~nb.any(axis=1))
    apart = (nf & nb & ~both).any(axis=1)  # some marker named by both, at points apart
    # where either pass renamed, its names change: a stretch between may keep the forward names
    cut = np.zeros(F + 1, bool)
    cut[np.flatnonzero(fwd.renamed)] = True
    cut[np.flatnonzero(bwd.renamed) + 1] = True  # a backward rename replaced the names after it
    for a, b in _runs(apart):
        to_b, _ = _verdict(fwd, bwd, a + np.flatnonzero(judged[a:b]))
        for a2, b2 in _pieces(a, b, cut):
            out[a2:b2] = to_b and not _verdict(fwd, bwd, a2 + np.flatnonzero(judged[a2:b2]))[1]
    return out


def _verdict(fwd: PassResult, bwd: PassResult, frames: np.ndarray) -> tuple[bool, bool]:
    """(the backward names fit clearly better, the forward ones do) over frames (indices): fit
    well (rms within ``FIT_GOOD_M``) and by ``FIT_RATIO`` times and ``FIT_GAIN_M2`` better
    than the other pass's (:func:`_misfit`)."""
    e_f, e_b = _misfit(fwd, frames), _misfit(bwd, frames)
    good = FIT_GOOD_M**2 * N_MARKERS * len(frames)
    return (bool(e_b <= good and e_b * FIT_RATIO < e_f and e_f - e_b > FIT_GAIN_M2),
            bool(e_f <= good and e_f * FIT_RATIO < e_b and e_b - e_f > FIT_GAIN_M2))


def _split_doubts(fwd: PassResult, bwd: PassResult, both_doubt: np.ndarray) -> np.ndarray:
    """(F, 8) bool: where both passes doubt their names of a marker and name it apart
    (both_doubt (F, 8) bool), the frames that take the backward name. Each pass was wrong next
    to its own rename: the forward pass before a rename after the run, the backward pass after
    one before it, so the run splits once, forward names first, backward names after, where
    the two passes' solves fit best (:func:`_misfits`: the split minimising the
    forward misfit before it plus the backward misfit from it). Two hands passing each other:
    each pass's tracking swapped them at the crossing, the forward pass renamed them 0.4 s
    later, the backward pass 0.1 s earlier; keeping the forward names throughout had them
    wrong for 0.4 s. Frames where either pass renamed a marker do not count: its solve there
    still leans on the names it held the frame before (the temporal term), and one such frame
    outweighed 0.4 s of mirrored legs that fit alike, 0.1 mm apart (006_04 seed 624: a
    dribbler's backward pass had both legs the other way round for 0.4 s after its own rename
    of the ankles, the forward pass for 0.1 s before its rename; the split took the backward
    legs for the whole 0.5 s, 92.2 -> 99.4 % of frames all right without those frames). Nothing
    without residuals. fwd, bwd: the two passes."""
    out = np.zeros(both_doubt.shape, bool)
    if fwd.residual is None or bwd.residual is None:
        return out
    for m in np.flatnonzero(both_doubt.any(axis=0)):
        for a, b in _runs(both_doubt[:, m]):
            e_f, e_b = _misfits(fwd, np.arange(a, b)), _misfits(bwd, np.arange(a, b))
            flux = (fwd.renamed[a:b] != 0) | (bwd.renamed[a:b] != 0)  # a pass's names change there
            e_f[flux] = e_b[flux] = 0.0
            cost = np.r_[0.0, np.cumsum(e_f)] + np.r_[np.cumsum(e_b[::-1])[::-1], 0.0]  # split at a + i
            s = a + int(np.argmin(cost))
            out[s:b, m] = True
    return out


def _shin_lengths(markers: np.ndarray, both: np.ndarray) -> np.ndarray:
    """(2,) m: the subject's left and right shin (knee to ankle marker) as the two passes measure
    it where they name both markers of the leg at the same points: the median over those frames
    of markers (F, 8, 3) (NaN where no frame has it); both: (F, 8) bool."""
    out = np.full(2, np.nan)
    for i, (_s, _w, kn, an) in enumerate(SIDES):
        at = both[:, kn] & both[:, an]
        if at.any():
            out[i] = float(np.median(np.linalg.norm(markers[at, kn] - markers[at, an], axis=1)))
    return out


def _whole_shins(take: np.ndarray, fwd: np.ndarray, bwd: np.ndarray, elsewhere: np.ndarray,
                 shin: np.ndarray) -> np.ndarray:
    """take (8,) bool (the names one frame takes from the backward pass) grown by the other
    marker of each leg of which only the knee or the ankle is taken, where the backward pass
    names it elsewhere (elsewhere (8,) bool), even a name either pass doubts or neither, when
    the leg named from the backward pass alone keeps the subject's shin length (shin (2,) m,
    :func:`_shin_lengths`) within ``SHIN_TOL_M`` and the mixed leg is off it by more than
    ``SHIN_OFF_M``: the knee of one pass and the ankle of the other are no leg. A dancer's
    legs swapped in the forward pass: the backward pass, right, doubted its ankles from a
    rename of its own that the forward pass's wrong names confirmed, and the mix took the
    backward knees and kept the forward ankles for 1 s; or the forward knees came right by
    tracking 0.5 s before a rule renamed its ankles, and the mix took the backward ankles and
    kept the forward knees, never doubted, for 1.2 s. fwd, bwd: (8, 3) the frame's names of
    each pass."""
    out = take.copy()
    for i, (_s, _w, kn, an) in enumerate(SIDES):
        if not np.isfinite(shin[i]) or take[kn] == take[an]:
            continue
        other = an if take[kn] else kn
        if not elsewhere[other]:
            continue
        d_b = float(np.linalg.norm(bwd[kn] - bwd[an]))
        mix_k, mix_a = (bwd[kn], fwd[an]) if take[kn] else (fwd[kn], bwd[an])
        d_m = float(np.linalg.norm(mix_k - mix_a))
        if abs(d_b - shin[i]) <= SHIN_TOL_M and abs(d_m - shin[i]) > SHIN_OFF_M:
            out[other] = True
    return out


def _halves(renamed: np.ndarray) -> np.ndarray:
    """(F,) int bits: every marker of each half of the body (the legs; the shoulders and wrists)
    in which renamed ((F,) int bits) has a marker."""
    return np.where(renamed & _LEGS, _LEGS, 0) | np.where(renamed & _UPPER, _UPPER, 0)


def _doubles(markers: np.ndarray) -> int:
    """Pairs of named markers (8, 3) within 1 cm of each other: one point named twice."""
    return int(np.count_nonzero(np.triu(_on_one_point(markers), 1)))


def _take_undoubled(markers: np.ndarray, k: int, idx: list[int], names: np.ndarray) -> bool:
    """Frame k of markers (F, 8, 3) takes names (len(idx), 3) for the markers idx, in place,
    unless that names one point twice more often than before (:func:`_doubles`); returns
    whether it did."""
    mixed = markers[k].copy()
    mixed[idx] = names
    if _doubles(mixed) > _doubles(markers[k]):
        return False
    markers[k] = mixed
    return True


def _parted(markers: np.ndarray, fwd: PassResult, bwd: PassResult, t: np.ndarray) -> np.ndarray:
    """(F,) bool: the frames of each run where the chosen wrists markers (F, 8, 3) are the
    backward pass's wrists the other way round, that take the backward names: the hands were
    together (wrists named within ``TOGETHER_M`` of each other by either pass) within
    ``PARTED_S`` s before the run and are not so again within ``PARTED_S`` s after it, where
    they are more than ``APART_M`` apart. Which hand is which as hands part no view tells
    (:meth:`Labeller.unseparated`), so each pass is right going into a meeting of the hands
    and guesses coming out of it: after one, in time, the forward pass guessed and the backward
    pass, which has not yet been through it, tracked. A dance's hands met at frame 433 and the
    forward pass named them the other way round for 0.3 s as they parted, 16-27 cm off, the
    backward pass right (005_06 seed 601, 96.5 -> 98.9 % of frames all right). Hands nearly
    together after the run (within ``APART_M``) may be the backward pass's own way out of a
    meeting: no verdict. t: (F,) s."""
    out = np.zeros(len(markers), bool)
    wr = [LW, RW]
    swapped = _within(markers[:, wr], bwd.markers[:, [RW, LW]]).all(axis=1)
    if not swapped.any():
        return out

    def apart(x: np.ndarray) -> np.ndarray:
        named = np.isfinite(x[:, wr]).all(axis=(1, 2))
        return np.where(named, np.linalg.norm(x[:, LW] - x[:, RW], axis=1), np.inf)

    sep = np.minimum(apart(fwd.markers), apart(bwd.markers))  # (F,) m, inf where neither names both
    for a, b in _runs(swapped):
        before = sep[np.searchsorted(t, t[a] - PARTED_S):a + 1].min()
        after = sep[b - 1:np.searchsorted(t, t[b - 1] + PARTED_S, side="right")].min()
        out[a:b] = before < TOGETHER_M and after > APART_M
    return out


def _guessed_shoulders(markers: np.ndarray, fwd: PassResult, bwd: PassResult, lin_b: np.ndarray,
                       t: np.ndarray) -> np.ndarray:
    """(F,) bool: the frames of each run where the chosen shoulders markers (F, 8, 3) are the
    backward pass's the other way round, that take the backward shoulders and wrists: the run
    starts at most ``PARTED_S`` after the forward pass left a shoulder unnamed while naming
    other markers (it picked the shoulders up again from stale predictions, a guess; not a
    blackout, after which an identification names them, :func:`choose`'s coin-flip rule), or
    right after such a run, and the backward names throughout the run descend from a clear
    identification (lineage >= ``CLEAR_M``, lin_b (F,)). A climber's shoulders, lost under the
    raised arms for 3 frames, were picked up the mirror way round by the forward pass, the
    wrists renamed to fit them; the backward pass, identified clearly after the blackout, had
    them right (001_14 on a fresh body, 4.2 s). t: (F,) s."""
    out = np.zeros(len(markers), bool)
    sh = [LS, RS]
    swapped = _within(markers[:, sh], bwd.markers[:, [RS, LS]]).all(axis=1)
    named = np.isfinite(fwd.markers).all(axis=2)
    lost = ~named[:, sh].all(axis=1) & named.any(axis=1)  # (F,) a shoulder lost, not a blackout
    taken = -1  # the last frame of the last run taken: a run right after it goes on with it
    for a, b in _runs(swapped):
        since = np.searchsorted(t, t[a] - PARTED_S)
        if (lost[since:a].any() or taken >= since) and (lin_b[a:b] >= CLEAR_M).all():
            out[a:b], taken = True, b - 1
    return out


def _unsure_mirrored(markers: np.ndarray, fwd: PassResult, bwd: PassResult) -> np.ndarray:
    """(F,) bool: the frames where the chosen legs markers (F, 8, 3) are the backward pass's
    the other way round (both knees, and each ankle both passes name), the forward pass unsure
    of their side (``PassResult.legs_unsure``: named afresh, the knees not yet seen apart the
    way the names say) and the backward pass sure (it tracked them from knees seen so): those
    take the backward legs. A dancer back from a blackout in a split leap, the forward
    identification named the legs the mirror way round, flagged them unsure, and kept them so
    for 0.8 s, up to 2 m off; the backward pass had tracked them right through (005_17 seed
    605, 91.4 -> 98.3 % of frames all right). Either pass without the flag: no frame. (The
    choice leaves out frames whose forward names descend from the standard pose.)"""
    out = np.zeros(len(markers), bool)
    if fwd.legs_unsure is None or bwd.legs_unsure is None:
        return out
    knees = _within(markers[:, [LK, RK]], bwd.markers[:, [RK, LK]]).all(axis=1)
    ankles = _within(markers[:, [LA, RA]], bwd.markers[:, [RA, LA]])
    both = np.isfinite(markers[:, [LA, RA]]).all(axis=2) & np.isfinite(bwd.markers[:, [RA, LA]]).all(axis=2)
    mirrored = knees & (ankles | ~both).all(axis=1)
    return mirrored & fwd.legs_unsure[:len(markers)].astype(bool) & ~bwd.legs_unsure[:len(markers)].astype(bool)


def choose(fwd: PassResult, bwd: PassResult, t: np.ndarray, window_s: float = 1.0,
           picked_up: bool = True, fit: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Per frame and marker the forward name, or the backward one where the forward pass
    doubted its own (a rename the backward naming confirms: the renamed markers, or every
    marker of their halves of the body where the two namings agree as a whole at the rename)
    and the backward pass names it and did not doubt it, or doubted it too but the split of
    the two doubts gives it the frame (:func:`_split_doubts`; not with ``fit`` False) (with
    the markers the forward pass left unnamed in that frame, and the rest of a leg whose knee
    and ankle the mix would take from different passes against the subject's shin:
    :func:`_whole_shins`), and
    every name of a frame the forward pass names nothing in (see the module docstring); the
    backward names across a gap in the forward names of a marker that they continue
    (:func:`_bridged`); and
    every name of a frame whose forward names descend from a coin-flip identification (margin
    < ``COIN_M``, not the take's first) while the backward ones descend from a clear one (>=
    ``CLEAR_M``), name a shoulder otherwise and name as many markers, or at least 4; the backward names from a forward
    rename on that both passes refute (:func:`_refuted`); a shoulder the forward pass left
    unnamed where it names a wrist on that shoulder's backward point (:func:`_wrist_on_shoulder`;
    the wrist its backward name where that names no point twice, else unnamed), also where a
    mix left it unnamed; the backward names of a and b
    where the forward pass names a, picked up after a gap, on the point the backward pass
    tracks as b (:func:`_picked_up`; not with ``picked_up`` False, as with two cameras). A
    forward name kept on a point whose backward name is taken for another marker, and that
    backward name, are dropped
    (:func:`_disputed`); a frame whose mixed names would still name one point twice more
    often than the forward names keeps the forward ones. Last, a short stretch where the chosen
    name leaves the backward one between frames the two agree on takes the backward name where
    it follows the marker's course better (:func:`_on_course`), and a run where the two name
    markers at points apart takes the backward names where they fit the solver clearly better
    (:func:`_fits_better`; not with ``fit`` False, as with two cameras), and the backward
    wrists where the chosen ones are those the other way round right after the hands met
    (:func:`_parted`; not with ``picked_up`` False), and the backward shoulders and wrists (and
    legs mirrored against them) where the forward pass picked the shoulders up the mirror way
    round after losing one (:func:`_guessed_shoulders`; not with ``picked_up`` False). Where
    the backward pass named a wrist on
    the point the forward pass names a shoulder and the chosen names took that view, the two
    keep their forward names (:func:`_shoulder_kept`; not with ``picked_up`` False: measured
    with four cameras only). Returns ((F, 8, 3)
    markers, (F,) bool: a name taken from the backward pass)."""
    nf = np.isfinite(fwd.markers).all(axis=2)
    nb = np.isfinite(bwd.markers).all(axis=2)
    both = _within(fwd.markers, bwd.markers)  # (F, 8) named at the same point by both passes
    same = both | (~nf & ~nb)  # (F, 8) the two passes name marker m alike
    # a rename is confirmed for the markers it renamed that the backward pass, tracking them
    # there (not renaming them itself, nor within NEXT_S after: its names there then descend
    # from its own rename of the same frames, both passes' identifications alike and as
    # likely wrong alike; a dancer's right knee and ankle, renamed by both onto the ankle's
    # point 2 frames apart, doubted 0.5 s of right forward legs, 005_05 on a fresh body),
    # names at the same points (a marker the rename left
    # unnamed: where the forward pass names it next, within NEXT_S); when it is confirmed for
    # all of them and the two namings agree as a whole (>= 4 markers named by both, none named
    # otherwise), for every marker of the halves of the body it renamed (the legs; the shoulders
    # and wrists)
    near = _within(fwd.markers, bwd.markers, ALIKE_M)  # one point (or one merged point split by each pass)
    alike = marker_bits(near | _renamed_to_none(fwd.renamed, nf, nb, both, t))
    agree = alike & ~_renamed_soon(bwd.renamed.astype(np.int64), t, NEXT_S)
    renamed = fwd.renamed.astype(np.int64)
    whole = ((nf & nb).sum(axis=1) >= 4) & (near | ~(nf & nb)).all(axis=1) & ((renamed & ~agree) == 0)
    confirmed = np.where(whole & (renamed != 0), _halves(renamed), renamed & agree)
    ident_f = _standard_pose_clear(fwd.identified)
    # the two passes agreeing as a whole settle a coin flip: later frames do not descend from it
    settled = ((nf & nb).sum(axis=1) >= 4) & same.all(axis=1)
    lin_f = _lineage(ident_f, nf.any(axis=1), forward=True, settled=settled, renamed=fwd.renamed)
    # names that descend from the standard pose's identification, with no agreement as a whole
    # of the two passes since (the backward pass never once named them so): no rename doubts them
    # ... back to where the two passes named the marker at the same point for HELD_S: the name the
    # rename replaced went wrong after that (a dancer's forward pass, right for 1 s, renamed the
    # right leg after naming it wrongly for 4 frames; the backward pass, which had named it
    # alike for 0.25 s before those, named it wrongly before that, and its names were taken:
    # 005_05 seed 621, 94.6 -> 99.1 %). A single frame alike is no such agreement (another
    # dance's forward legs mirrored for 0.5 s after a blackout, one knee alike for a frame)
    doubt_f = np.where(lin_f >= STANDARD_POSE_M, 0,
                       _doubted(confirmed, nf.any(axis=1), t, window_s, forward=True, own=renamed,
                                confirmed=_held(both, t, HELD_S, bit_markers(renamed)))
                       | _apart_before(confirmed, same, t, own=renamed))
    # and the other way round: a backward rename counts where the forward pass names those
    # markers at the same points (tracking them, not renaming them, nor having identified or
    # renamed them within NEXT_S before: a dancer's crossed ankles, named the wrong way round
    # by an identification after a blackout, confirmed a backward rename to the same wrong
    # names 4 frames later, and the backward pass's right names of the 0.6 s after were
    # doubted: 005_12 seed 623, 92.8 -> 98.6 %)
    fresh_f = renamed if fwd.identified is None else \
        renamed | np.where(np.isfinite(fwd.identified), _UPPER | _LEGS, 0)  # an identification names all
    agree_b = alike & ~_renamed_soon(fresh_f, t, NEXT_S, forward=True)
    # ... back only to where the forward pass last named the marker at the same point (in its
    # travel, the backward names the rename replaced went wrong after it). For forward renames
    # only an agreement held HELD_S (above): the passes agreeing before one are often both
    # wrong alike (module docstring)
    doubt_b = _doubted(bwd.renamed.astype(np.int64) & agree_b, nb.any(axis=1), t, window_s, forward=False,
                       confirmed=both, own=bwd.renamed)
    lin_b = _lineage(bwd.identified, nb.any(axis=1), forward=False, renamed=bwd.renamed)
    flip = (lin_f < COIN_M) & (lin_b >= CLEAR_M) & (nb.sum(axis=1) >= np.minimum(nf.sum(axis=1), 4)) \
        & ~same[:, [LS, RS]].all(axis=1)
    bridged = _bridged(nf, nb, both, ~nf.any(axis=1) & nb.any(axis=1) & (doubt_b == 0))
    # (a marker both leave unnamed while they name others is named alike; a blackout is no agreement)
    unnamed_alike = ~nf & ~nb & (nf.any(axis=1) & nb.any(axis=1))[:, None]
    refuted = _refuted(fwd.renamed, nf, nb, both | unnamed_alike, t)
    shin = _shin_lengths(fwd.markers, both)
    doubted_f = bit_markers(doubt_f)  # (F, 8) the markers the forward pass doubts
    split_b = _split_doubts(fwd, bwd, bit_markers(doubt_f & doubt_b) & nf & nb & ~same) if fit \
        else np.zeros(nf.shape, bool)
    markers = fwd.markers.copy()
    from_b = np.zeros(len(t), bool)
    for k in range(len(t)):
        if not nf[k].any():
            if nb[k].any() and not doubt_b[k]:
                markers[k], from_b[k] = bwd.markers[k], True
            continue
        if flip[k] and not doubt_b[k] and _doubles(bwd.markers[k]) <= _doubles(fwd.markers[k]):
            markers[k], from_b[k] = bwd.markers[k], True
            continue
        sure_b = nb[k] & (~bit_markers(doubt_b[k]) | split_b[k])  # backward names not doubted, or split so
        take = (doubted_f[k] & ~same[k] | refuted[k]) & sure_b
        if take.any():
            take |= ~nf[k] & sure_b  # a naming found wrong in part: its gaps are filled in too
        take |= bridged[k] & sure_b
        if take.any():
            take = _whole_shins(take, fwd.markers[k], bwd.markers[k], nb[k] & ~same[k], shin)
        drop = refuted[k] & ~nb[k] & nf[k]  # refuted where the backward pass names it nowhere
        if not (take.any() or drop.any()):
            continue
        mixed = markers[k].copy()
        mixed[take] = bwd.markers[k][take]
        mixed[drop] = np.nan
        mixed[_disputed(mixed, take)] = np.nan
        if _doubles(mixed) <= _doubles(fwd.markers[k]):
            markers[k], from_b[k] = mixed, True
    for a, b, k0, k1 in _picked_up(fwd.markers, bwd.markers) if picked_up else []:
        for k in range(k0, k1 + 1):
            from_b[k] |= _take_undoubled(markers, k, [a, b], bwd.markers[k, [a, b]])
    for w, s, hit in _wrist_on_shoulder(fwd.markers, bwd.markers):
        hit &= ~np.isfinite(markers[:, s]).all(axis=1)  # still unnamed (or disputed in a mix)
        markers[hit, s] = bwd.markers[hit, s]
        markers[hit & _within(markers[:, w], bwd.markers[:, s]), w] = np.nan
        # ... and the wrist its backward name, where that names no point twice: the hand lost
        # at the shoulder is found where the backward pass tracked it (a dancer's left wrist
        # unnamed for 0.5 s while the backward pass named it right, 005_11 seed 652)
        for k in np.flatnonzero(hit & ~np.isfinite(markers[:, w]).all(axis=1) & nb[:, w]):
            _take_undoubled(markers, k, [w], bwd.markers[k, [w]])
        from_b |= hit
    markers, course = _on_course(markers, bwd.markers, t, unsure=bwd.unseparated)
    better = _fits_better(fwd, bwd, nf, nb, both) if fit else np.zeros(len(t), bool)
    markers[better] = bwd.markers[better]
    parted = _parted(markers, fwd, bwd, t) if picked_up else np.zeros(len(t), bool)
    markers[np.ix_(parted, [LW, RW])] = bwd.markers[np.ix_(parted, [LW, RW])]
    legs = _unsure_mirrored(markers, fwd, bwd) if picked_up else np.zeros(len(t), bool)
    # not names from the standard pose with no agreement since: there the backward pass is the
    # one to doubt (a child-sized climber's knees merged in the standard pose, never confirmed)
    legs &= ~(lin_f >= STANDARD_POSE_M)
    markers[np.ix_(legs, [LK, RK, LA, RA])] = bwd.markers[np.ix_(legs, [LK, RK, LA, RA])]
    guessed = _guessed_shoulders(markers, fwd, bwd, lin_b, t) if picked_up else np.zeros(len(t), bool)
    markers[np.ix_(guessed, [LS, RS, LW, RW])] = bwd.markers[np.ix_(guessed, [LS, RS, LW, RW])]
    # the forward legs mirrored there were named against the facing of those shoulders
    legs_too = guessed & _within(fwd.markers[:, [LK, RK]], bwd.markers[:, [RK, LK]]).all(axis=1)
    markers[np.ix_(legs_too, [LK, RK, LA, RA])] = bwd.markers[np.ix_(legs_too, [LK, RK, LA, RA])]
    if picked_up:
        _shoulder_kept(markers, fwd.markers, bwd.markers)
    return markers, from_b | course | better | parted | legs | guessed


def loose_of(markers: np.ndarray, fwd: PassResult, bwd: PassResult) -> np.ndarray | None:
    """(F, 8) bool: the chosen names markers (F, 8, 3) whose position is rough, as the pass that
    named the marker at that point said (``PassResult.loose``); None when neither pass says."""
    return _as_named(markers, (fwd.markers, fwd.loose), (bwd.markers, bwd.loose))


def unseparated_of(markers: np.ndarray, fwd: PassResult, bwd: PassResult) -> np.ndarray:
    """(F, 8) bool: the chosen names markers (F, 8, 3) that no view saw apart, as the pass that
    named the marker at that point said (``PassResult.unseparated``), where both wrists are
    so: the pair is output unnamed (:func:`relabel_both_ways`)."""
    out = _as_named(markers, (fwd.markers, fwd.unseparated), (bwd.markers, bwd.unseparated))
    if out is None:
        return np.zeros(markers.shape[:2], bool)
    pair = out[:, [LW, RW]].all(axis=1)
    out[:] = False
    out[pair, LW] = out[pair, RW] = True
    return out


def _as_named(markers: np.ndarray, *passes: tuple[np.ndarray, np.ndarray | None]) -> np.ndarray | None:
    """(F, 8) bool: per chosen marker of markers (F, 8, 3), the flag (F, 8) of the pass (its
    markers (F, 8, 3), its flags or None) that named the marker at that point, the first pass's
    word where several did; None when no pass has flags."""
    if all(flags is None for _m, flags in passes):
        return None
    out = np.zeros(markers.shape[:2], bool)
    for named, flags in reversed(passes):
        if flags is not None:
            at = _within(markers, named, 1e-6)
            out[at] = flags[at]
    return out


def relabel_both_ways(server: Server, packets: list[list], t: np.ndarray, fwd: PassResult,
                      progress=None) -> tuple[np.ndarray, dict] | None:
    """The two-way labelling of a take the forward (live) pass ``server`` has processed.
    packets: per frame (F) a list per rig camera of MarkerPacket or None; t: (F,) s; fwd: the
    forward pass's names; progress: optional, updated once per frame of the backward pass.
    Returns ((F, 13, 3) joints, extras as process_frames gives them, plus ``from_backward``
    (F,) bool), or None when there is no second pass (no subject measured, no solver)."""
    bwd = backward_pass(server, packets, t, progress, end_facing(fwd, t))
    if bwd is None:
        log.info("no subject measured: labelled forwards only")
        return None
    # with two cameras every point is a 2-view point and names are picked up after gaps all the
    # time in both passes: the backward track is no better evidence (2-camera benchmark: -0.12
    # points, frames with a wrong name 3578 -> 3700 with the rule)
    # ... and every 2-view point fits some body: the solver's fit is no verdict either (2
    # cameras, 14 takes of the benchmark's saved passes: 1116 -> 1161 frames not all right)
    markers, take_b = choose(fwd, bwd, t, picked_up=len(server.rig) >= 3, fit=len(server.rig) >= 3)
    log.info("two-way labelling: %d of %d frames named from the backward pass", int(take_b.sum()), len(t))
    # hands together no view separates: solved loosely, output unnamed (a gap, not a coin flip)
    gap = unseparated_of(markers, fwd, bwd)
    loose = loose_of(markers, fwd, bwd)
    loose = gap if loose is None else loose | gap
    joints, results = solve_both_ways(server.reconstructor.again(), markers, t, loose=loose)
    bounds = np.array([r.bounds for r in results], float).reshape(len(t), -1)
    if gap.any():
        log.info("two-way labelling: both wrists left unnamed on %d frames (no view saw them apart)",
                 int(gap[:, LW].sum()))
    markers = np.where(gap[:, :, None], np.nan, markers)
    extra = {"markers": markers, "residual": np.array([r.residual for r in results], float),
             "n_markers": np.isfinite(markers).all(axis=2).sum(axis=1),
             "label_margin": np.where(take_b, bwd.margin, fwd.margin), "from_backward": take_b,
             "legs_unsure": legs_unsure_of(markers, fwd, bwd), "wrists_unseparated": gap[:, LW]}
    extra["joint_bound"] = mirrored_wrists(mirrored_legs(widened(bounds, disputed_m(fwd, bwd)), joints,
                                                         extra["legs_unsure"]), joints, gap[:, LW])
    if len(server.rig) < 3:  # left and right are a guess there
        extra["joint_bound"] = mirrored_pairs(extra["joint_bound"], joints)
    return joints, extra


def legs_unsure_of(markers: np.ndarray, fwd: PassResult, bwd: PassResult) -> np.ndarray:
    """(F,) bool: the frames whose chosen leg names markers (F, 8, 3) may be each other's. A
    pass that names the legs as chosen (each within ``ALIKE_M``: two markers on one merged
    point are placed beside it a little differently by each pass) and is sure of them
    (``PassResult.legs_unsure``: it has tracked them from knees named clearly apart, earlier in
    its direction of travel) makes them sure; else they are unsure when a pass that names them
    so, or, the choice mixing the passes' names, either pass, is unsure."""
    F = len(markers)
    legs = [LK, RK, LA, RA]
    named = np.isfinite(markers[:, legs]).all(axis=2)
    sure = np.zeros(F, bool)
    unsure_same = np.zeros(F, bool)
    unsure_any = np.zeros(F, bool)
    matched = np.zeros(F, bool)
    for p in (fwd, bwd):
        if p.legs_unsure is None:
            continue
        flag = p.legs_unsure[:F].astype(bool)
        same = ((_within(markers[:, legs], p.markers[:F, legs], ALIKE_M) == named).all(axis=1)) & named.any(axis=1)
        sure |= same & ~flag
        unsure_same |= same & flag
        unsure_any |= flag
        matched |= same
    return ~sure & np.where(matched, unsure_same, unsure_any) & named.any(axis=1)


def disputed_m(fwd: PassResult, bwd: PassResult) -> np.ndarray:
    """(F, 8) m: how far apart the two passes put each marker where both name it (0 elsewhere).
    Whichever name was chosen, the marker's joint may be that far off: two passes that saw the
    same points and named them differently are a doubt the chosen pose's bounds must carry (on
    fresh seeds, 4 cameras, 196 takes: a confidently wrong joint in 0.85 -> 0.33 % of confident
    frames, joints flagged unsure 5.0 -> 7.4 %)."""
    both = np.isfinite(fwd.markers).all(axis=2) & np.isfinite(bwd.markers).all(axis=2)
    return np.where(both, np.linalg.norm(np.nan_to_num(fwd.markers - bwd.markers), axis=2), 0.0)
