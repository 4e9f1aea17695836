"""Offline labelling from both ends of a take (samba_server/both_ways.py): the backward pass
is the real labelling and solver run on the packets in reverse order."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.skeleton import JOINT_NAMES, MARKER_JOINT
from samba_common.wire import UNLABELLED, MarkerPacket
from samba_mote.sim.motion import DEFAULT_LENGTHS, synthetic_motion
from samba_server.both_ways import (AGREED_S, APART_S, COURSE_M, COURSE_S, JOIN_S, NEXT_S, PassResult, backward_pass,
                                    choose, end_facing, legs_unsure_of, loose_of, relabel_both_ways)
from samba_server.labelling.rigid import LA, LK, LS, LW, RA, RK, RS, RW
from samba_server.recon.bounds import CONFIDENT_M
from samba_server.recon.reconstruct import Reconstructor, solve_frames
from samba_server.server import Server, ServerConfig

FPS = 60.0
MIRROR = [RS, LS, RW, LW, RK, LK, RA, LA]  # names of the mirror image, by marker


def _in_a_row(F: int) -> np.ndarray:
    """(F, 8, 3) m: the eight markers standing still 1 m apart along x, the namings the choice
    tests start from."""
    out = np.zeros((F, 8, 3))
    out[:, :, 0] = np.arange(8)
    return out


def _packets(rig, markers: np.ndarray, t: float, rng) -> list[MarkerPacket]:
    """One unlabelled MarkerPacket per camera: markers (8, 3) projected, NaN rows unseen."""
    out = []
    seen = np.isfinite(markers).all(axis=1)
    for cam in rig.cameras:
        uv = cam.project(np.where(seen[:, None], markers, 0.0))[seen] + rng.normal(0, 0.1, (int(seen.sum()), 2))
        out.append(MarkerPacket(cam.name, 0, int(t * 1e9), 160, 120, 100, np.full(len(uv), UNLABELLED, np.uint8),
                                uv.astype(np.float32), np.full(len(uv), 9, np.uint16),
                                np.zeros(len(uv), np.uint8)))
    return out


def _take(seconds: float = 4.0, blackout: tuple[int, int] = (110, 140)):
    """Markers (F, 8, 3) of the synthetic motion with a blackout (frames [a, b) unseen), the
    packets per frame, t (F,) s, and the forward (live) pass over them with its server."""
    rig = default_rig(4)
    joints, t = synthetic_motion(seconds, FPS)
    truth = joints[:, list(MARKER_JOINT)]
    rng = np.random.default_rng(5)
    packets = []
    for k in range(len(t)):
        m = truth[k] if not blackout[0] <= k < blackout[1] else np.full((8, 3), np.nan)
        packets.append(_packets(rig, m, float(t[k]), rng))
    server = Server(rig, None, Reconstructor(lengths=DEFAULT_LENGTHS), ServerConfig(max_lag_ms=0.0))
    F = len(t)
    fwd = PassResult(np.full((F, 8, 3), np.nan), np.zeros(F, np.int64), np.full(F, np.nan))
    for k in range(F):
        markers, _mask, q = server.label_packets(packets[k], float(t[k]))
        fwd.markers[k] = server.solve_markers(markers, float(t[k]))[0]
        fwd.renamed[k], fwd.margin[k] = q.renamed, q.margin_m
    return truth, packets, t, server, fwd


def _right(named: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(F,) bool: every marker named and within 2 cm of its truth."""
    return (np.linalg.norm(named - truth, axis=2) <= 0.02).all(axis=1)


def test_a_mirror_naming_after_a_blackout_is_replaced_by_the_backward_one():
    """After a blackout the forward pass names the mirror image (as a dancer who turned in the
    dark is named) for 0.4 s until a later check renames the markers. The backward pass reaches
    those frames tracking from the end of the take: the output takes its names there, keeps the
    forward ones where both agree, and solves every frame."""
    truth, packets, t, server, fwd = _take()
    assert _right(fwd.markers[:110], truth[:110]).mean() > 0.95  # the forward pass itself is right
    wrong = np.arange(142, 166)  # from the first identification after the blackout for 0.4 s
    bad = PassResult(fwd.markers.copy(), fwd.renamed.copy(), fwd.margin.copy())
    bad.markers[wrong] = fwd.markers[wrong][:, MIRROR]
    bad.renamed[wrong[-1] + 1] = 0xFF  # renamed by an audit 0.4 s later
    assert not _right(bad.markers[wrong], truth[wrong]).any()
    joints, extra = relabel_both_ways(server, packets, t, bad)
    assert _right(extra["markers"][wrong], truth[wrong]).all()
    assert extra["from_backward"][wrong].all()
    assert not extra["from_backward"][:100].any()  # agreed: the forward names stay
    out = ~np.isin(np.arange(len(t)), np.arange(110, 145))
    assert np.isfinite(joints[out]).all()
    err = np.linalg.norm(joints[wrong][:, list(MARKER_JOINT)] - truth[wrong], axis=2)
    assert err.max() < 0.1  # the pose follows the backward names


def test_the_backward_pass_names_a_take_that_ends_facing_away_from_where_it_began():
    """The backward pass identifies the subject afresh at the take's last frame. The standard
    pose faces +Y, but a take may end facing anywhere: a dancer who ended facing -Y was named
    mirrored, all four pairs, for the whole of her last kick. Here the subject turns 180 degrees
    over 1.7 s and stops facing -Y; the backward pass, told the facing the forward pass named at
    the end (from the standard pose's clear identification), names her right, and mirrored
    when it assumes the standard pose's facing."""
    rig = default_rig(4)
    joints, t = synthetic_motion(1.67, FPS, turn_deg=180.0)
    truth = joints[:, list(MARKER_JOINT)]
    rng = np.random.default_rng(5)
    packets = [_packets(rig, truth[k], float(t[k]), rng) for k in range(len(t))]
    server = Server(rig, None, Reconstructor(lengths=DEFAULT_LENGTHS), ServerConfig(max_lag_ms=0.0))
    F = len(t)
    fwd = PassResult(np.full((F, 8, 3), np.nan), np.zeros(F, np.int64), np.full(F, np.nan), np.full(F, np.nan))
    for k in range(F):
        markers, _mask, q = server.label_packets(packets[k], float(t[k]))
        fwd.markers[k] = server.solve_markers(markers, float(t[k]))[0]
        fwd.renamed[k], fwd.margin[k] = q.renamed, q.margin_m
        if q.mode == "identified":
            fwd.identified[k] = q.margin_m
    assert _right(fwd.markers, truth).all()
    facing = end_facing(fwd, t)
    assert facing is not None and facing[1] < -0.9
    assert _right(backward_pass(server, packets, t, facing=facing).markers, truth).all()
    assert not _right(backward_pass(server, packets, t).markers[-10:], truth[-10:]).any()
    # no facing from names whose shoulders a rule renamed in the last second ...
    fwd.renamed[F - 30] = 1 << LS
    assert end_facing(fwd, t) is None
    fwd.renamed[F - 30] = 0
    # ... nor from names that descend from a coin-flip identification (after a blackout)
    fwd.identified[F // 2] = 0.0
    fwd.renamed[F // 2] = 0xFF
    assert end_facing(fwd, t) is None


def test_a_naming_the_solver_cannot_fit_gives_way_to_the_backward_one_that_it_fits():
    """For 0.5 s the forward pass names the right knee on the left knee's point and leaves the
    left knee unnamed (knees passing each other in a dribble; no rule renamed anything, so no
    two-way rule doubts it), while the backward pass names both knees right. Solved, the
    forward names put the right knee where the subject's right shin cannot reach: the solver's
    residual says which naming is a body. The backward names are taken there, and only there.
    Where the forward naming fits as well (as knees swapped both ways may), where the backward
    one fits no body well either, or where the forward one was not solved, it stays; without
    residuals the other two-way rules leave those frames wrong."""
    truth, packets, t, server, fwd = _take(blackout=(0, 0))
    bwd = backward_pass(server, packets, t)
    assert _right(bwd.markers[20:], truth[20:]).all()
    wrong = np.arange(150, 180)
    bad = PassResult(fwd.markers.copy(), fwd.renamed.copy(), fwd.margin.copy())
    bad.markers[wrong, RK] = bad.markers[wrong, LK]
    bad.markers[wrong, LK] = np.nan
    rec = server.reconstructor.again(server.subject)
    bad.residual = np.array([r.residual for r in solve_frames(rec, bad.markers, t, range(len(t)))])
    assert np.nanmedian(bad.residual[wrong]) > 3 * np.nanmedian(bwd.residual[wrong])
    markers, from_b = choose(bad, bwd, t)
    assert _right(markers[wrong], truth[wrong]).all() and from_b[wrong].all()
    assert np.array_equal(markers[:150], bad.markers[:150], equal_nan=True)
    swapped = replace(bad, markers=fwd.markers.copy(), residual=bwd.residual)  # knees swapped, fitting as well
    swapped.markers[np.ix_(wrong, [LK, RK])] = fwd.markers[np.ix_(wrong, [RK, LK])]
    assert np.array_equal(choose(swapped, bwd, t)[0][wrong], swapped.markers[wrong])
    # the better of two bad fits is no verdict (the database fits an uncrossed naming of crossed
    # feet better than the truth): backward names 1 cm off are not taken from forward ones 3 cm off
    poor_b = replace(bwd, residual=np.where(np.isin(np.arange(len(t)), wrong), 0.01, bwd.residual))
    poor_f = replace(swapped, residual=np.where(np.isin(np.arange(len(t)), wrong), 0.03, bwd.residual))
    assert np.array_equal(choose(poor_f, poor_b, t)[0][wrong], swapped.markers[wrong])
    assert _right(choose(poor_f, bwd, t)[0][wrong], truth[wrong]).all()  # against a good fit they give way
    # nor frames whose forward solve judged nothing (no residual: the subject still being measured)
    unjudged = replace(bad, residual=np.where(np.isin(np.arange(len(t)), wrong), np.nan, bad.residual))
    assert not _right(choose(unjudged, bwd, t)[0][wrong], truth[wrong]).any()
    assert not _right(choose(replace(bad, residual=None), bwd, t)[0][wrong], truth[wrong]).any()  # the rules alone


def test_the_fit_judges_each_run_of_disagreeing_names_on_its_own():
    """The backward pass names the wrists the wrong way round in frames 90-119 (fitting as
    well as the forward names: a swap no solve tells), then leaves the left wrist unnamed to
    frame 149 where the forward pass names it, and from 150 to 179 the forward pass names the
    right knee on the left knee's point (fitting no body). The two runs where the passes name
    markers at points apart are judged apart: the knees take the backward names, the wrists keep
    the forward ones (judged as one stretch, the bad knees gave the backward pass the wrists too:
    a fresh body's wrists swapped for 0.5 s)."""
    truth, packets, t, server, fwd = _take(blackout=(0, 0))
    bwd = backward_pass(server, packets, t)
    assert _right(bwd.markers[20:], truth[20:]).all()
    knees, wrists, hidden = np.arange(150, 180), np.arange(90, 120), np.arange(120, 150)
    bad = PassResult(fwd.markers.copy(), fwd.renamed.copy(), fwd.margin.copy())
    bad.markers[knees, RK] = bad.markers[knees, LK]
    bad.markers[knees, LK] = np.nan
    rec = server.reconstructor.again(server.subject)
    bad.residual = np.array([r.residual for r in solve_frames(rec, bad.markers, t, range(len(t)))])
    swapped = replace(bwd, markers=bwd.markers.copy(), residual=bwd.residual.copy())
    swapped.markers[np.ix_(wrists, [LW, RW])] = bwd.markers[np.ix_(wrists, [RW, LW])]
    swapped.residual[wrists] = bad.residual[wrists]  # as well as the forward names
    swapped.markers[hidden, LW] = np.nan
    markers, _from_b = choose(bad, swapped, t)
    assert _right(markers[knees], truth[knees]).all()
    assert _right(markers[wrists], truth[wrists]).all() and _right(markers[hidden], truth[hidden]).all()


def test_the_fit_judges_apart_the_stretches_between_the_passes_renames():
    """The forward pass names the legs the other way round in frames 100-129 until a rule swaps
    them back at 130, fitting no body (2 cm rms); the backward pass, coming from the take's end,
    names them the other way round in frames 130-139 until its own rule swaps them back at 129
    (in its direction of travel, frame 140 -> 139), fitting a body at 8 mm. The two stretches
    touch: one run of disagreeing names, whose backward names fit better as a whole. Taken for
    all of it, the legs were wrong in 130-139 (a swordplay's last 1.2 s); there, between the
    two renames, the forward names fit clearly better (2 mm) and are kept: every frame takes
    the names that are right."""
    truth, packets, t, server, fwd = _take(blackout=(0, 0))
    bwd = backward_pass(server, packets, t)
    legs, mirror = [LK, RK, LA, RA], [RK, LK, RA, LA]
    rec = server.reconstructor.again(server.subject)

    def mirrored(p: PassResult, frames: np.ndarray, renamed_at: int, residual_m: float) -> PassResult:
        out = PassResult(p.markers.copy(), p.renamed.copy(), p.margin.copy())
        out.markers[np.ix_(frames, legs)] = p.markers[np.ix_(frames, mirror)]
        out.renamed[renamed_at] |= sum(1 << m for m in legs)
        out.residual = np.array([r.residual for r in solve_frames(rec, p.markers, t, range(len(t)))])
        out.residual[frames] = residual_m
        return out

    bad_f = mirrored(fwd, np.arange(100, 130), 130, 0.02)
    bad_b = mirrored(bwd, np.arange(130, 140), 129, 0.008)
    assert (bad_f.residual[130:140] < 0.0025).all()
    markers, _from_b = choose(bad_f, bad_b, t)
    assert _right(markers[95:150], truth[95:150]).all()


def test_a_marker_the_two_passes_put_apart_is_not_confident_whichever_name_is_kept():
    """For 40 frames the forward pass names the left wrist 30 cm from where the backward pass
    names it, and no rule decides between them (no rename, no residuals to compare): the forward
    name is kept, but the output's bounds of the left wrist and elbow say it may be 30 cm off,
    while the legs, which both passes name alike, stay confident."""
    truth, packets, t, server, fwd = _take(blackout=(0, 0))
    bad = PassResult(fwd.markers.copy(), fwd.renamed.copy(), fwd.margin.copy())
    off = np.arange(150, 190)
    bad.markers[off, LW] += [0.0, 0.3, 0.0]
    _joints, extra = relabel_both_ways(server, packets, t, bad)
    assert np.allclose(extra["markers"][off, LW], bad.markers[off, LW])
    bound = extra["joint_bound"][off]
    left_arm = [JOINT_NAMES.index("left_wrist"), JOINT_NAMES.index("left_elbow")]
    assert (bound[:, left_arm] >= 0.29).all()
    legs = [JOINT_NAMES.index(n) for n in ("left_knee", "right_knee", "left_ankle", "right_ankle")]
    assert (bound[:, legs] < CONFIDENT_M).all()  # the doubt stays with the arm


def test_only_a_naming_its_own_pass_found_wrong_is_replaced():
    """Two namings differ up to frame 200 and agree after it. The forward one stays, except in
    the second before the forward pass renamed its markers at 200 to what the backward pass
    names (there the backward one is taken, for the markers renamed), unless the backward pass
    renamed its own in the second after to names the forward pass confirms; a rename the backward pass does not confirm (names
    otherwise, or renamed itself at that frame or within ``NEXT_S`` after it: its names there
    descend from its own rename of the same frames) changes nothing; a rename of some markers where
    the two namings agree as a whole speaks for their half of the body (the legs; the shoulders
    and wrists), not the other half; a frame the forward pass names nothing in takes the
    backward names."""
    F = 301
    t = np.arange(F) / FPS
    a = np.zeros((F, 8, 3))
    b = a.copy()
    b[140:200] += 0.5  # the passes agree up to frame 139 (a rename doubts back to there)
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    fwd, bwd = PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F))
    markers, from_b = choose(fwd, bwd, t)
    assert not from_b.any() and np.allclose(markers, 0.0)  # nobody doubted: the live names
    ren_f[200] = 0xFF  # forward found its names wrong at frame 200, and renamed them as backward does
    _m, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 200))
    ren_b[150] = 0xFF  # backward found its own wrong at 150, to names the forward pass does not
    _m, from_b = choose(fwd, bwd, t)  # give there: not confirmed, no doubt
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 200))
    a[150] = b[150]  # confirmed (the forward pass names them so there): its names after it are doubted
    _m, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 150))
    a[150], ren_b[150] = 0.0, 0
    ren_b[200] = 0xFF  # the backward pass renamed them at the same frame: its names there are no check
    _m, from_b = choose(fwd, bwd, t)
    assert not from_b.any()
    ren_b[200] = 0
    ren_b[202] = 0xFF  # ... nor 2 frames later (its names at 200 descend from that rename) ...
    _m, from_b = choose(fwd, bwd, t)
    assert not from_b.any()
    ren_b[202] = 0
    ren_b[200 + int(NEXT_S * FPS) + 1] = 0xFF  # ... but one more than NEXT_S later they are
    _m, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 200))
    ren_b[:] = 0
    b[200:] += 0.5  # the backward pass names otherwise after the rename too: not confirmed
    _m, from_b = choose(fwd, bwd, t)
    assert not from_b.any()
    b[200:] -= 0.5
    b[200:, [LW, RW]] += 0.3  # the namings agree on all but the wrists at the rename ...
    ren_f[200] = (1 << LA) | (1 << RA)  # ... that swapped the ankles only: only they are taken
    b[140:200, [LA, RA]] = b[140:200, [RA, LA]] + [[0.0, 0.0, 0.1], [0.0, 0.0, 0.2]]
    b[150, LA] = np.nan  # a name the backward pass does not give is not taken away
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 200))
    assert np.allclose(markers[150, LA], 0.0)
    b[150, LA] = b[149, LA]
    markers, from_b = choose(fwd, bwd, t)
    assert np.allclose(markers[140:200, [LA, RA]], b[140:200, [LA, RA]]) and np.allclose(markers[140:200, :LA], 0.0)
    ren_f[200] = 0xFF  # renamed every marker: all but the wrists are confirmed
    markers, from_b = choose(fwd, bwd, t)
    others = [LS, RS, LK, RK, LA, RA]
    assert np.allclose(markers[140:200, others], b[140:200, others]) and np.allclose(markers[140:200, [LW, RW]], 0.0)
    b[200:, [LW, RW]] -= 0.3  # agreeing as a whole: every marker the backward way
    markers, from_b = choose(fwd, bwd, t)
    assert np.allclose(markers[140:200], b[140:200])
    ren_f[200] = (1 << LA) | (1 << RA)  # agreeing as a whole at a rename of the ankles: the legs
    markers, from_b = choose(fwd, bwd, t)  # the backward way, the shoulders and wrists as they were
    legs = [LK, RK, LA, RA]
    assert np.allclose(markers[140:200, legs], b[140:200, legs]) and np.allclose(markers[140:200, :LK], 0.0)
    ren_f[200] = 0
    a[20:30] = np.nan  # forward names nothing: the backward names fill in
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(20, 30)) and np.array_equal(markers[20:30], b[20:30])


def test_names_from_a_coin_flip_identification_give_way_to_a_clear_backward_naming():
    """After a blackout (frames 100-129, nothing named) the forward pass identifies the subject
    with a margin of 0 (the mirror image scored the same) and tracks those names to the end of
    the take, renaming nothing; the backward pass tracks from a clear identification at the
    end. Where they differ the backward names win. Not when the forward identification was
    only unclear (not a coin flip), nor when the backward one was no clearer, nor over the
    names descending from the standard pose (the take's first identification), nor where the
    backward pass names fewer than 4 markers (and fewer than the forward pass), nor where the
    two name the shoulders alike."""
    from samba_server.both_ways import CLEAR_M, COIN_M

    F = 301
    t = np.arange(F) / FPS
    right = np.arange(8 * 3, dtype=float).reshape(8, 3) / 10.0
    a = np.repeat(right[None], F, axis=0)
    a[131:] = right[MIRROR]  # forward: the mirror image after the blackout
    b = np.repeat(right[None], F, axis=0)
    b[:100] += 0.05  # backward differs before the blackout too (a slip of its own)
    a[100:130] = b[100:130] = np.nan
    idf, idb = np.full(F, np.nan), np.full(F, np.nan)
    idf[0], idf[130], idb[300], idb[99] = 0.0, 0.0, CLEAR_M, 0.5
    fwd = PassResult(a, np.zeros(F, np.int64), np.zeros(F), idf)
    bwd = PassResult(b, np.zeros(F, np.int64), np.zeros(F), idb)
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, F))
    assert np.allclose(markers[131:], right) and np.allclose(markers[:100], right)
    idf[130] = COIN_M  # unclear, not a coin flip: the forward names stay
    assert not choose(fwd, bwd, t)[1].any()
    idf[130], idb[300] = 0.0, CLEAR_M - 0.01  # the backward identification not clear either
    assert not choose(fwd, bwd, t)[1].any()
    idb[300] = CLEAR_M
    assert not choose(PassResult(a, fwd.renamed, fwd.margin), bwd, t)[1].any()  # no margins known: as before
    b[200:, :5] = np.nan  # the backward pass names 3 markers there: those frames stay forward
    _m, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, 200))
    # two namings that differ in the legs only, the shoulders alike: the forward names stay (a
    # dancer standing with her legs crossed at the take's end was identified clearly but
    # uncrossed by the backward pass, while the coin flip after the blackout had named her right)
    b[200:] = right
    a[131:] = right
    a[131:, [4, 5, 6, 7]] = right[[5, 4, 7, 6]]
    assert not choose(fwd, bwd, t)[1].any()


def test_a_rename_that_left_the_marker_unnamed_is_checked_where_it_is_named_next():
    """The forward pass names the left wrist on the wrong point up to frame 200, then finds the
    name wrong and, with no other point for it yet, leaves it unnamed (as a hand hidden beside
    the other shoulder was, on a take of a new body); from frame 202 it names the wrist where
    the backward pass does. The backward names are taken for the wrong stretch. A wrist named
    again only after NEXT_S, or named where the backward pass does not, confirms nothing."""
    F = 301
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[140:200, LW] += 0.5  # wrong for the forward pass ...
    a[200:202, LW] = np.nan  # ... unnamed when it found that out
    ren_f = np.zeros(F, np.int64)
    ren_f[200] = 1 << LW
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, np.zeros(F, np.int64), np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 202))  # the gap bridged too
    assert np.allclose(markers[140:202], b[140:202])
    late = a.copy()
    late[200:200 + int(NEXT_S * FPS) + 2, LW] = np.nan  # named again only after NEXT_S
    _m, from_b = choose(PassResult(late, ren_f, np.zeros(F)), PassResult(b, np.zeros(F, np.int64), np.zeros(F)), t)
    assert not from_b[:200].any()
    elsewhere = a.copy()
    elsewhere[202:, LW] += 0.2  # named again, but not where the backward pass names it
    _m, from_b = choose(PassResult(elsewhere, ren_f, np.zeros(F)), PassResult(b, np.zeros(F, np.int64), np.zeros(F)), t)
    assert not from_b[:200].any()


def test_a_gap_in_the_forward_names_is_filled_where_the_backward_pass_names_the_same_marker():
    """The forward pass leaves the left wrist unnamed for a third of a second (a hand hidden
    from a view, a point the points stage did not make) where the backward pass names it. Both
    passes name the wrist at the same point on either side of the gap, so the backward name
    across it is the same marker: it is taken. A backward naming that differs at both edges of
    the gap is another marker's track and is not; a break in the backward names splits the
    fill at it."""
    F = 100
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[40:60, LW] = np.nan
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(40, 60)) and np.allclose(markers, b)
    other = b.copy()
    other[:, LW] += 0.3  # the backward pass follows something else
    _m, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(other, none, np.zeros(F)), t)
    assert not from_b.any()
    other[:50, LW] = b[:50, LW]  # the same marker up to frame 49, then it jumps away
    other[50, LW] = np.nan
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(other, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(40, 50)) and np.allclose(markers[40:50], b[40:50])
    # after a blackout the forward pass names nothing for two frames (the backward names are
    # taken there), then picks the subject up without the right wrist, which the backward pass
    # names on from those frames: its name is taken up to its break (and from there on from
    # where the two passes name it alike again)
    a, b = b.copy(), b.copy()
    a[:30] = b[:30] = np.nan  # the blackout
    a[30:32] = np.nan  # the forward pass names nothing yet
    a[32:70, RW] = np.nan
    b[50, RW] = np.nan  # the backward pass loses the wrist for a frame
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.r_[30:50, 51:70])
    assert np.allclose(markers[30:50], b[30:50]) and not np.isfinite(markers[50, RW]).any()


def test_a_forward_rename_both_passes_refute_is_undone_until_they_agree_again():
    """Both passes name the legs alike up to frame 49; at frame 50 a rule of the forward pass
    swaps the two legs' names (as on a climb of another body), and the backward pass, tracking
    from the end of the take, names them as both did before. The forward pass's own past and
    the backward pass's future agree against that rule: the backward names are taken from the
    rename until the forward pass names the legs as the backward one again (frame 80), also
    where the backward pass renamed the legs shortly before, in its direction of travel, since
    the forward pass names them as it does between (:func:`_doubted` with ``confirmed``). A
    backward pass that named them otherwise before the rename refutes nothing, nor one that
    named them alike for less than AGREED_S (right after a blackout both passes can be wrong
    the same way)."""
    F = 120
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    legs = [LK, LA, RK, RA]
    a[50:80, legs] = b[50:80][:, [RK, RA, LK, LA]]  # the forward pass swaps the legs at frame 50
    ren_f = np.zeros(F, np.int64)
    ren_f[50] = sum(1 << m for m in legs)
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(50, 80)) and np.allclose(markers, b)
    ren_b = np.zeros(F, np.int64)
    ren_b[40] = ren_f[50]  # the backward pass renamed the legs at 40, but the forward pass confirms
    _m, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(50, 80))  # its names from 41 on: no doubt
    other = b.copy()
    other[:50, legs] += 0.3  # the passes did not name the legs alike before the rename
    _m, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(other, none, np.zeros(F)), t)
    assert not from_b.any()
    seen = 50 - int(AGREED_S * FPS) // 2  # a blackout up to here: both name the legs alike for
    other[:seen] = np.nan  # half AGREED_S before the rename (after a blackout both can be wrong alike)
    other[seen:50] = b[seen:50]
    blind = a.copy()
    blind[:seen] = np.nan
    _m, from_b = choose(PassResult(blind, ren_f, np.zeros(F)), PassResult(other, none, np.zeros(F)), t)
    assert not from_b[seen:].any()


def test_a_point_the_two_passes_name_as_different_markers_is_named_neither_way():
    """Up to frame 200 the forward pass names the left wrist elsewhere and the right wrist on the
    left wrist's point; at 200 it finds the left wrist's name wrong and renames it to the point
    the backward pass names it at. In the second before, the backward left wrist is taken, on
    the point the forward right wrist still holds: the passes dispute that point, so neither
    name stands there (the mix used to be refused whole, keeping both wrong forward names)."""
    F = 301
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[140:200, LW] += 0.5
    a[140:200, RW] = b[140:200, LW]
    b[200:, LA] += 0.3  # the namings do not agree as a whole at the rename: the left wrist is taken alone
    ren_f = np.zeros(F, np.int64)
    ren_f[200] = 1 << LW
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 200))
    assert np.isnan(markers[140:200, [LW, RW]]).all()
    others = [LS, RS, LK, RK, LA, RA]
    assert np.allclose(markers[140:200, others], a[140:200, others]) and np.allclose(markers[:140], a[:140])


def test_a_confirmed_rename_doubts_the_names_back_to_where_the_passes_last_agreed():
    """The forward pass names the left wrist on the right shoulder's point from frame 40 (a
    climber's hand at the other shoulder) and gives the point back at frame 170, 2.2 s later;
    the backward pass names it right throughout. The whole stretch back to frame 40, where the
    passes last agreed, takes the backward name, not only the second before the rename; a
    stretch longer than APART_S only its last APART_S."""
    F = 400
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[40:170, LW] = b[40:170, RS] + [0.0, 0.0, 0.2]  # near the shoulder, not on it
    ren_f = np.zeros(F, np.int64)
    ren_f[170] = 1 << LW
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(40, 170)) and np.allclose(markers, b)
    long = b.copy()
    long[:350, LW] += 0.2  # wrong from the start, renamed at 350
    ren_f[170], ren_f[350] = 0, 1 << LW
    _m, from_b = choose(PassResult(long, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(350 - int(APART_S * FPS), 350))


def test_a_rename_is_confirmed_where_the_backward_pass_names_the_marker_on_the_same_merged_point():
    """The forward pass has the legs the wrong way round from frame 40 and renames them at 100,
    where both knees share one merged point that each pass splits either side of it along its
    own tracks' predictions: the backward pass's knees 1.5 cm from the forward pass's, on the
    same side. That confirms the rename (points are never closer than 3.5 cm; the two sides of
    a split at least 4 cm apart), and the stretch back to frame 40 takes the backward names, as
    with two names on one point (005_04 on a fresh body: 92.9 -> 99.1 % of frames all right).
    Knees split onto the other side confirm nothing."""
    F = 200
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    legs = [LK, RK, LA, RA]
    a = b.copy()
    a[40:100, legs] = b[40:100][:, [RK, LK, RA, LA]]
    ren_f = np.zeros(F, np.int64)
    ren_f[100] = (1 << LK) | (1 << RK)
    none = np.zeros(F, np.int64)
    split = b.copy()
    split[100, [LK, RK]] += [0.015, 0.0, 0.0]  # the backward pass's split of the same point
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(split, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(40, 100)) and np.allclose(markers[:100], b[:100])
    split[100, [LK, RK]] = b[100, [RK, LK]]  # split the other way round: the backward pass disputes it
    _m, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(split, none, np.zeros(F)), t)
    assert not from_b[:100].any()


def test_a_refuted_rename_takes_back_the_rest_of_its_half_of_the_body_that_went_with_it():
    """Both passes name the legs alike (the right knee hidden from both now and then, which is
    no disagreement) until a rule of the forward pass swaps the ankles at frame 50; the next
    frame its tracking takes the knees along (no rename); the backward pass names the legs as
    before throughout and the right knee not at all from frame 60 (hidden). The ankles'
    rename is refuted (:func:`_refuted`) and the knees that went with it take the backward
    names too, until the two agree again at 80; where the backward pass leaves the right knee
    unnamed, the forward pass's name for it on the left knee's point is dropped (005_17 on a
    fresh body: the left knee left unnamed for 0.6 s, 92.3 -> 99.0 % of frames all right)."""
    F = 120
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    b[10:40:7, RK] = np.nan  # hidden from both passes now and then
    a = b.copy()
    a[50:80, [LA, RA]] = b[50:80][:, [RA, LA]]
    a[51:80, [LK, RK]] = b[51:80][:, [RK, LK]]
    ren_f = np.zeros(F, np.int64)
    ren_f[50] = (1 << LA) | (1 << RA)
    none = np.zeros(F, np.int64)
    hidden = b.copy()
    hidden[60:80, RK] = np.nan
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(hidden, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(50, 80))
    assert np.allclose(markers, hidden, equal_nan=True)


@pytest.mark.parametrize("case", ["guessed", "no gap", "backward a coin flip"])
def test_shoulders_picked_up_the_mirror_way_round_after_a_gap_take_the_backward_body(case):
    """A climber's shoulders are lost under the raised arms (frames 100-102, the forward pass
    names neither); the forward pass picks them up the mirror way round from its stale
    predictions at 103, renames the wrists to fit them at 106 and, against that facing, the
    legs at 130, and keeps it all so until 200. The backward pass, named from a clear
    identification at the take's end, has them right throughout, and both namings fit a body
    alike. Each pass is right going into the gap and guesses coming out: after it, in time,
    the backward names of the shoulders and wrists are taken, and of the legs where the forward
    ones are the mirror (001_14 on a fresh body, seed 612: 54.2 -> 97.4 % of frames all right).
    Not where the mirror names did not come out of a gap of the forward shoulders, nor where
    the backward names descend from a coin flip."""
    F = 300
    t = np.arange(F) / FPS
    truth = _in_a_row(F)
    a = truth.copy()
    a[100:103, [LS, RS]] = np.nan
    a[103:200, [LS, RS]] = truth[103:200][:, [RS, LS]]
    a[106:200, [LW, RW]] = truth[106:200][:, [RW, LW]]
    a[130:200, [LK, RK, LA, RA]] = truth[130:200][:, [RK, LK, RA, LA]]
    if case == "no gap":
        a[100:103, [LS, RS]] = truth[100:103][:, [RS, LS]]  # the shoulders swapped from 100 on, never lost
    ren_f = np.zeros(F, np.int64)
    ren_f[106] = (1 << LW) | (1 << RW)
    ren_f[130] = (1 << LK) | (1 << RK) | (1 << LA) | (1 << RA)
    idb = np.full(F, np.nan)
    idb[F - 1] = 0.0 if case == "backward a coin flip" else 0.1
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(truth, np.zeros(F, np.int64), np.zeros(F), idb),
                             t)
    if case == "guessed":
        assert np.allclose(markers, truth) and from_b[103:200].all()
    else:
        assert np.allclose(markers[103:200, [LS, RS]], a[103:200, [LS, RS]])


def test_a_swap_of_both_legs_mended_in_two_steps_is_doubted_back_to_where_it_began():
    """The forward pass names both legs the other way round from frame 100 (a dancer's legs
    after a turn); at frame 197 its knees come right by tracking, with no rename, and at 200 a
    rule renames the ankles, where the two passes agree as a whole. The knees are doubted back
    to frame 100 too, not only the second before the rename: they were swapped with the
    ankles. Knees that had agreed for longer than JOIN_S before the rename are doubted only
    in the second before it, as any marker of a rename's half of the body (here the backward
    knees are 6 cm off the shin before that second, so the legs are not taken whole either:
    see the two tests of whole legs below)."""
    F = 300
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[100:200, [LK, RK, LA, RA]] = b[100:200, [RK, LK, RA, LA]]
    a[197:200, [LK, RK]] = b[197:200, [LK, RK]]  # the knees came right by themselves
    ren_f = np.zeros(F, np.int64)
    ren_f[200] = (1 << LA) | (1 << RA)
    none = np.zeros(F, np.int64)
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.allclose(markers, b)
    early = a.copy()
    k = 200 - int(JOIN_S * FPS) - 3
    early[k:200, [LK, RK]] = b[k:200, [LK, RK]]  # right for longer: a mend of their own
    off = b.copy()
    off[100:140, [LK, RK]] += [0.06, 0.0, 0.0]
    markers, _from_b = choose(PassResult(early, ren_f, np.zeros(F)), PassResult(off, none, np.zeros(F)), t)
    assert np.allclose(markers[:, [LA, RA]], b[:, [LA, RA]])
    assert np.allclose(markers[140:, [LK, RK]], b[140:, [LK, RK]])
    assert np.allclose(markers[100:140, [LK, RK]], early[100:140, [LK, RK]])



def _dancer_legs(F: int) -> tuple[np.ndarray, np.ndarray]:
    """t (F,) s and the true markers (F, 8, 3) of a standing subject: the upper body's markers
    1 m apart on a line, the legs side by side (shins 45 cm; a knee of one leg and the ankle of
    the other 53-54 cm apart)."""
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    legs = np.array([[-0.1, 0.0, 0.5], [0.1, 0.1, 0.5], [-0.1, -0.15, 0.08], [0.1, 0.3, 0.1]])  # LK RK LA RA
    b[:, [LK, RK, LA, RA]] = legs + [5.0, 0.0, 0.0]
    return t, b


def test_a_leg_is_taken_whole_from_one_pass_where_a_knee_of_one_and_an_ankle_of_the_other_break_the_shin():
    """A dancer's legs: the forward pass renames the ankles the wrong way round at frame 90,
    tracks the knees onto the wrong legs from 110 and renames all four right at 200. The
    backward pass is right but for frames 99-100, where a rename of its own at 100 made its
    ankles agree with the forward pass's wrong ones (tracked for 10 frames since its rename:
    more than ``NEXT_S``, a confirmation); so it doubts its ankles for the second after. The
    mix took its knees and kept the forward ankles, a knee on one leg and an ankle on the
    other, 9-11 cm off the shin length the two passes measure together: the backward ankles
    come with the backward knees. Backward ankles that break the shin themselves do not."""
    F = 300
    t, b = _dancer_legs(F)
    a = b.copy()
    a[90:200, [LA, RA]] = b[90:200, [RA, LA]]
    a[110:200, [LK, RK]] = b[110:200, [RK, LK]]
    bwd = b.copy()
    bwd[99:101, [LA, RA]] = b[99:101, [RA, LA]]
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[90] = (1 << LA) | (1 << RA)
    ren_f[200] = (1 << LK) | (1 << RK) | (1 << LA) | (1 << RA)
    ren_b[100] = (1 << LA) | (1 << RA)
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(bwd, ren_b, np.zeros(F)), t)
    assert np.allclose(markers[110:200], b[110:200])
    off = bwd.copy()
    off[101:200, [LA, RA]] += [0.0, 0.0, 0.06]  # the backward ankles 6 cm off there
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(off, ren_b, np.zeros(F)), t)
    assert np.allclose(markers[110:161, [LK, RK]], off[110:161, [LK, RK]])
    assert np.allclose(markers[110:161, [LA, RA]], a[110:161, [LA, RA]])


def test_knees_a_pass_does_not_doubt_come_with_the_ankles_taken_from_the_other_where_the_mix_breaks_the_shins():
    """A dancer's legs after a blackout: the forward pass names both legs the other way round
    from frame 100, its knees come right by tracking at 170 (0.5 s before, a mend of their own)
    and a rule renames the ankles at 200. The backward pass is right throughout. The renamed
    ankles are doubted back to frame 100 and taken from the backward pass; the knees, never
    doubted, stayed forward: a knee on one leg and an ankle on the other, each leg 26 cm off
    the subject's shin, for 1.2 s (005_09 seed 601 after a change of the points lost 36 % of
    its frames so). A leg whose backward knee and ankle keep the shin is taken whole."""
    F = 300
    t, b = _dancer_legs(F)
    a = b.copy()
    a[100:200, [LK, RK, LA, RA]] = b[100:200, [RK, LK, RA, LA]]
    a[170:200, [LK, RK]] = b[170:200, [LK, RK]]
    ren_f = np.zeros(F, np.int64)
    ren_f[200] = (1 << LA) | (1 << RA)
    none = np.zeros(F, np.int64)
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.allclose(markers, b)


@pytest.mark.parametrize("case", ["parted", "parted along a hilt", "they meet again", "two cameras"])
def test_wrists_the_forward_pass_swapped_as_the_hands_parted_take_the_backward_names(case):
    """Hands together 5 cm apart in frames 100-110 (a clap, a hilt), parting to 30 cm by frame
    130 (14 cm, both hands on a sword's hilt). Which hand is which as they part no view tells:
    the forward pass, coming out of the meeting, names the wrists the other way round from
    frame 111 to 149; the backward pass, which reaches those frames before it goes through the
    meeting, names them right. Those frames take the backward wrists. Not where the hands
    meet again right after the run (the backward pass may then be the one coming out of a
    meeting), nor with two cameras."""
    F = 300
    t = np.arange(F) / FPS
    apart = 0.14 if case == "parted along a hilt" else 0.30
    sep = np.full(F, apart)
    sep[100:111] = 0.05
    sep[111:130] = np.linspace(0.05, apart, 19)
    if case == "they meet again":
        sep[150:160] = 0.05
    b = _in_a_row(F)  # the other markers 1 m apart
    b[:, LW] = [2.5, 0.0, 1.2] - sep[:, None] * [0.0, 0.5, 0.0]
    b[:, RW] = [2.5, 0.0, 1.2] + sep[:, None] * [0.0, 0.5, 0.0]
    a = b.copy()
    a[111:150, [LW, RW]] = b[111:150, [RW, LW]]
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t,
                             picked_up=case != "two cameras")
    if case.startswith("parted"):
        assert np.allclose(markers, b) and np.array_equal(np.flatnonzero(from_b), np.arange(111, 150))
    else:
        assert np.allclose(markers, a) and not from_b.any()


@pytest.mark.parametrize("case", ["forward unsure", "both unsure", "forward sure", "two cameras", "standard pose"])
def test_legs_the_forward_pass_is_unsure_of_take_the_backward_names_it_is_sure_of_the_other_way_round(case):
    """Back from a blackout in a split leap, the forward identification names the legs the
    mirror way round in frames 100-149 and flags them unsure (their side not yet seen); the
    backward pass tracked them right through and is sure. Those frames take the backward legs.
    Not where the backward pass is unsure too, nor where the forward pass is sure, nor with
    two cameras, nor where the forward names descend from the standard pose's identification
    and the two passes have not once agreed as a whole since (a child-sized climber's knees
    merged in the standard pose, so never seen apart: the forward legs, right, stayed unsure,
    and the backward pass, come into the standard pose mirrored, took them for 1.1 s; 001_14
    seed 611, 63.3 -> 75.1 % of frames all right)."""
    F = 300
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[100:150, [LK, RK, LA, RA]] = b[100:150, [RK, LK, RA, LA]]
    a[120:125, LA] = np.nan  # an ankle one pass leaves unnamed does not stop the rest
    unsure_f, unsure_b = np.zeros(F, bool), np.zeros(F, bool)
    unsure_f[100:150] = case != "forward sure"
    unsure_b[:] = case == "both unsure"
    none = np.zeros(F, np.int64)
    identified = np.full(F, np.nan)
    if case == "standard pose":
        identified[0] = 0.1  # the take's first identification, the standard pose's
        b = b.copy()
        b[:150, [LW, RW]] += [0.0, 0.0, 0.05]  # the backward wrists apart: no agreement as a whole
    markers, from_b = choose(PassResult(a, none, np.zeros(F), identified, legs_unsure=unsure_f),
                             PassResult(b, none, np.zeros(F), legs_unsure=unsure_b), t,
                             picked_up=case != "two cameras")
    if case == "forward unsure":
        assert np.allclose(markers, b) and np.array_equal(np.flatnonzero(from_b), np.arange(100, 150))
    else:
        assert np.array_equal(np.isnan(markers), np.isnan(a)) and np.allclose(markers[~np.isnan(a)], a[~np.isnan(a)])
        assert not from_b.any()


def _swapped_by_both(F: int, pair: tuple[int, int], cross: int) -> tuple:
    """t (F,) s, the true markers (F, 8, 3) in a row, and two namings with their renames
    (a, b, ren_f, ren_b), each with the pair (m, n) the wrong way round next to its own
    rename: the forward one from frame ``cross`` until it renames them at 158, the backward
    one (walking back in time) from cross - 1 until it renames them at 127."""
    t = np.arange(F) / FPS
    truth = _in_a_row(F)
    a, b = truth.copy(), truth.copy()
    m, n = pair
    a[cross:158, [m, n]] = truth[cross:158, [n, m]]
    b[128:cross, [m, n]] = truth[128:cross, [n, m]]
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[158] = ren_b[127] = (1 << m) | (1 << n)
    return t, truth, a, b, ren_f, ren_b


def test_where_both_passes_doubt_a_name_the_fit_splits_the_stretch_between_their_renames():
    """Two hands pass each other at frame 135 and each pass's tracking swaps them there: the
    forward pass has the wrists the wrong way round in 135-157 and renames them at 158, the
    backward pass (walking back in time) in 134-128 and renames them at 127. In 128-157 each
    doubts its own wrists and the two never agree: keeping the forward names had them wrong
    for 135-157. The stretch splits where the passes' fits say: forward names before 135,
    backward after. Without residuals the forward names stay."""
    F = 300
    t, truth, a, b, ren_f, ren_b = _swapped_by_both(F, (LW, RW), 135)
    res_f, res_b = np.full(F, 0.008), np.full(F, 0.008)  # no body fits well: no verdict of the fit
    res_f[135:158] = res_b[128:135] = 0.012  # the swapped wrists fit worse
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F), residual=res_f),
                              PassResult(b, ren_b, np.zeros(F), residual=res_b), t)
    assert np.allclose(markers, truth)
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
    assert np.allclose(markers, a)


def test_the_fit_split_of_two_doubts_does_not_count_the_frames_a_pass_renamed_in():
    """A dribbler's knees: the backward pass (walking back in time) has them the wrong way
    round in 128-150 and renames them at 127, the forward pass in 151-157 and renames them at
    158; both doubt them through 128-157. Mirrored legs fit alike: the right names fit 0.1 mm
    better. At 128 the backward pass renamed the ankles, and there the forward solve fit 13 mm
    against 7 mm: counted, that one frame gave the split to the backward names from 128 on
    (006_04 seed 624); without it the split falls at 151."""
    F = 300
    t, truth, a, b, ren_f, ren_b = _swapped_by_both(F, (LK, RK), 151)
    ren_b[128] = (1 << LA) | (1 << RA)
    res_f, res_b = np.full(F, 0.008), np.full(F, 0.008)
    res_f[128:151], res_b[128:151] = 0.0014, 0.0015  # the mirrored legs fit alike
    res_f[151:158], res_b[151:158] = 0.003, 0.001
    res_f[128], res_b[128] = 0.013, 0.007
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F), residual=res_f),
                              PassResult(b, ren_b, np.zeros(F), residual=res_b), t)
    assert np.allclose(markers, truth)


def test_names_from_the_standard_pose_the_backward_pass_never_agreed_with_are_not_doubted():
    """A climb: the forward pass names the standard pose from frame 0 (a clear identification)
    and holds the names; its right shoulder goes wrong at 108 and an identification renames the
    shoulders at 114. The backward pass came into the standard pose mirrored (every marker on
    its mirror partner's point) and never named it otherwise until 107. The rename doubted the
    shoulders back to where the passes last agreed, the whole standard pose, and there the mix
    left both shoulders unnamed (the backward right shoulder on the forward left one's point).
    Names that descend from the standard pose, the two passes never once agreeing on them since,
    are not doubted. Once the passes agreed as a whole, the standard pose's names are doubted as
    any others."""
    F = 300
    t = np.arange(F) / FPS
    truth = _in_a_row(F)
    a = truth.copy()
    a[108:112, RS] += [0.0, 0.0, 0.3]
    bwd = truth.copy()
    bwd[:107] = truth[:107][:, MIRROR]
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[114] = (1 << LS) | (1 << RS)
    ren_b[106] = 0xFF  # walking back in time, the backward pass renamed into the mirror image there
    ident = np.full(F, np.nan)
    ident[0] = ident[114] = 0.12
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F), ident), PassResult(bwd, ren_b, np.zeros(F)), t)
    assert np.allclose(markers[:108], truth[:108])
    assert np.allclose(markers[108:112, RS], truth[108:112, RS])  # the wrong shoulder still gives way
    agreed = bwd.copy()
    agreed[5] = truth[5]  # the two passes agree as a whole at frame 5 ...
    agreed[107:112] = truth[107:112][:, MIRROR]  # ... and name the left shoulder alike again 2 frames only
    markers, _from_b = choose(PassResult(a, ren_f, np.zeros(F), ident), PassResult(agreed, ren_b, np.zeros(F)), t)
    assert np.allclose(markers[60:100, [LS, RS]], agreed[60:100, [LS, RS]])  # the rename's doubt holds


def test_a_forward_rename_doubts_its_names_only_back_to_where_the_passes_agreed_for_a_while():
    """A dance: the forward pass names the right leg right for 1 s, wrongly for 4 frames, and
    renames it (confirmed: the backward pass names it at the same points after the rename).
    The backward pass named it alike for 0.25 s before those 4 frames, and wrongly before that
    (walking back in time, its own rename there went wrong). The names the forward rename
    replaced went wrong after the two passes' agreement: the doubt stops there and the
    backward pass's wrong names are not taken (they were for 0.4 s: 005_05 seed 621, 94.6 ->
    99.1 % of frames all right). An agreement of one frame (``HELD_S``: 0.1 s) stops nothing."""
    F = 300
    t = np.arange(F) / FPS
    truth = _in_a_row(F)
    a = truth.copy()
    a[200:204, RK] = truth[200:204, RA]  # forward: the knee on the ankle's point for 4 frames, renamed at 204
    ren_f = np.zeros(F, np.int64)
    ren_f[204] = (1 << RK) | (1 << RA)
    for agree_from in (185, 199):  # the backward names alike from there (0.25 s; a frame)
        b = truth.copy()
        b[160:agree_from, RK] = truth[160:agree_from, RA]  # backward: wrong before that, renamed there
        b[160:agree_from, RA] = np.nan
        ren_b = np.zeros(F, np.int64)
        ren_b[agree_from - 1] = (1 << RK) | (1 << RA)
        markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
        assert np.allclose(markers[200:204], truth[200:204])  # the forward pass's wrong frames mended
        if agree_from == 185:
            assert np.allclose(markers[:200], truth[:200]) and not from_b[:200].any()
        else:
            assert from_b[160:199].all()  # doubted through a frame alike: the backward names taken


def test_a_backward_rename_doubts_its_names_only_up_to_where_the_forward_pass_confirmed_them():
    """The backward pass (walking back in time) named the left wrist wrong from frame 130 to
    101 and renamed it at 100; from 131 on the forward pass names it at the same point: there
    the backward name is confirmed, so the rename says nothing about the frames after 130.
    The forward pass names the left wrist wrong from 140 and finds that out at 170: the whole
    stretch 140-169 takes the backward name (it used to keep the wrong forward name up to
    frame 160, one second after the backward rename), while 101-130 stay forward."""
    F = 301
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    b[101:131, LW] += [0.0, 0.0, 0.5]  # backward wrong there, renamed at 100
    a[140:170, LW] += [0.0, 0.0, 0.3]  # forward wrong there, renamed at 170
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[170], ren_b[100] = 1 << LW, 1 << LW
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(140, 170))
    assert np.allclose(markers[140:170], b[140:170]) and np.allclose(markers[101:131], a[101:131])
    b[131:140, LW] += [0.0, 0.0, 0.5]  # never confirmed since the rename: doubted for its second
    _m, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(161, 170))


def test_a_backward_rename_to_names_just_identified_after_a_blackout_is_not_confirmed_by_them():
    """A dancer's ankles: after a blackout (frames 130-145) the forward pass identifies the
    body at 146 with the ankles crossed the wrong way round and keeps them so until it renames
    them at 200. The backward pass, right from the take's end, renamed them at 150 (walking
    back in time) to the same wrong names. Forward names 4 frames old, from an identification
    of the same ambiguous points, are no confirmation of that rename: frames 151-199 take the
    backward names (005_12 seed 623: 92.8 -> 98.6 % of frames all right). The same forward
    names tracked, not identified, within ``NEXT_S`` do confirm it, and keep the forward names."""
    F = 301
    t = np.arange(F) / FPS
    truth = _in_a_row(F)
    crossed = truth[:, [LA, RA]][:, ::-1]
    a, b = truth.copy(), truth.copy()
    a[130:146] = b[130:146] = np.nan
    a[146:200, [LA, RA]] = crossed[146:200]
    b[146:151, [LA, RA]] = crossed[146:151]
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[200] = ren_b[150] = (1 << LA) | (1 << RA)
    bwd = PassResult(b, ren_b, np.zeros(F), identified=np.full(F, np.nan))
    for identified_at in (146, None):
        identified = np.full(F, np.nan)
        if identified_at is not None:
            identified[identified_at] = 0.7
        fwd = PassResult(a, ren_f, np.zeros(F), identified=identified)
        markers, _from_b = choose(fwd, bwd, t)
        assert np.allclose(markers[146:151], a[146:151])  # both wrong alike
        if identified_at is not None:
            assert np.allclose(markers[151:200], truth[151:200])
        else:
            assert np.allclose(markers[151:200], a[151:200])


def test_a_short_slip_of_the_forward_name_gives_way_to_the_backward_one_that_keeps_the_course():
    """The left knee moves 1 cm per frame; both passes name it alike except for a few frames
    where the forward pass slips onto the right knee's point (or drops the name) while the
    backward pass keeps following it. There the backward name, on the knee's course between the
    agreed frames, is taken. Not for a stretch longer than COURSE_S, not a backward name farther
    than COURSE_M from that course, not onto a point another chosen name holds, and not a
    backward name its pass says no view saw apart from its partner (002_07 on a fresh body: a
    hilt's left wrist took the right one's point for 0.3 s; 90.1 -> 93.2 % of frames all
    right)."""
    F = 120
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    b[:, LK, 1] = 0.01 * np.arange(F)  # the left knee walks
    none = np.zeros(F, np.int64)

    def chosen(a: np.ndarray, bwd: np.ndarray) -> np.ndarray:
        return choose(PassResult(a, none, np.zeros(F)), PassResult(bwd, none, np.zeros(F)), t)[0]

    a = b.copy()
    a[50:56, LK] = b[50:56, RK] + [0.0, 0.0, 0.2]  # the forward pass slips near the right knee for 6 frames
    a[60:63, LK] = np.nan  # and drops the name for 3
    markers = chosen(a, b)
    assert np.allclose(markers, b)
    n = int(COURSE_S * FPS) + 2  # too long to tell by the course
    a[70:70 + n, LK] = b[70:70 + n, RK] + [0.0, 0.0, 0.2]
    assert np.allclose(chosen(a, b)[70:70 + n], a[70:70 + n])
    far = b.copy()
    far[50:56, LK] += [0.0, 0.0, COURSE_M + 0.05]  # the backward name off the course too
    assert np.allclose(chosen(a, far)[50:56], a[50:56])
    held = b.copy()
    held[60:63, LK] = b[60:63, LA]  # on the point the chosen left ankle holds
    assert np.isnan(chosen(a, held)[60:63, LK]).all()
    # nor a backward name its pass saw no view part from its partner (hands together on a hilt)
    unseparated = np.zeros((F, 8), bool)
    unseparated[50:56, LK] = True
    markers = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F), unseparated=unseparated), t)[0]
    assert np.allclose(markers[50:56], a[50:56]) and np.allclose(markers[60:63], b[60:63])


def test_a_wrist_on_the_point_the_backward_pass_names_its_unnamed_shoulder_gives_it_back():
    """A hand lost at the other shoulder (a dribble): from frame 100 to 130 the forward pass
    names the left wrist on the right shoulder's point and leaves the right shoulder unnamed,
    with no rename; the backward pass names the right shoulder there and the left wrist
    elsewhere. The shoulder takes its backward name, and the wrist its backward one (005_11 seed
    652: the wrist unnamed 0.5 s while the backward pass had it right, 90.1 -> 97.6 %), unless
    that names a point twice: then it is unnamed. Where the forward pass names the shoulder
    too (two markers on one point), nothing changes."""
    F = 240
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    a = b.copy()
    a[100:130, LW] = b[100:130, RS]
    a[100:130, RS] = np.nan
    a[160:180, LW] = b[160:180, RS]  # both on one point, the shoulder named: left alone
    none = np.zeros(F, np.int64)
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(100, 130))
    assert np.allclose(markers[100:130, RS], b[100:130, RS]) and np.allclose(markers[100:130, LW], b[100:130, LW])
    others = [m for m in range(8) if m not in (RS, LW)]
    assert np.allclose(markers[100:130, others], a[100:130, others])
    assert np.allclose(markers[:100], a[:100]) and np.allclose(markers[130:], a[130:])
    on_ankle = b.copy()
    on_ankle[100:130, LW] = b[100:130, LA]  # the backward wrist on the point the left ankle holds
    markers = choose(PassResult(a, none, np.zeros(F)), PassResult(on_ankle, none, np.zeros(F)), t)[0]
    assert np.allclose(markers[100:130, RS], b[100:130, RS]) and np.isnan(markers[100:130, LW]).all()
    assert np.allclose(markers[100:130, LA], a[100:130, LA])


def test_a_backward_wrist_on_the_forward_shoulder_point_does_not_displace_the_shoulder():
    """The backward names are taken after a coin-flip identification (the passes never agree
    after it), but from frame 150 to 170 the backward pass names the left wrist on the point
    the forward pass names the right shoulder, and leaves that shoulder unnamed (a hand lost at
    the shoulder, 005_03 on a fresh body). There the right shoulder and the left wrist keep
    their forward names; every other name of those frames is still the backward one. Not
    where the forward pass's other shoulder is on a point the backward pass names as another
    marker."""
    from samba_server.both_ways import CLEAR_M

    F = 301
    t = np.arange(F) / FPS
    right = np.arange(8 * 3, dtype=float).reshape(8, 3) / 10.0
    a = np.repeat(right[None], F, axis=0)
    b = a.copy()
    a[100:130] = b[100:130] = np.nan
    b[131:, :, 2] += 0.05  # the passes never agree after the coin flip: the backward names win
    b[150:170, LW] = a[150:170, RS]
    b[150:170, RS] = np.nan
    idf, idb = np.full(F, np.nan), np.full(F, np.nan)
    idf[0], idf[130], idb[300] = 0.0, 0.0, CLEAR_M
    fwd = PassResult(a, np.zeros(F, np.int64), np.zeros(F), idf)
    bwd = PassResult(b, np.zeros(F, np.int64), np.zeros(F), idb)
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, F))
    assert np.allclose(markers[150:170, [RS, LW]], a[150:170, [RS, LW]])
    others = [m for m in range(8) if m not in (RS, LW)]
    assert np.allclose(markers[131:, others], b[131:, others])
    assert np.allclose(markers[np.r_[131:150, 170:F]], b[np.r_[131:150, 170:F]])
    # the forward pass's left shoulder on the point the backward pass names the right wrist:
    # its upper body is named one place on (a climb, 001_14 on a fresh body), no hand was lost
    shifted = a.copy()
    shifted[150:170, LS] = b[150:170, RW]
    markers, _f = choose(PassResult(shifted, fwd.renamed, fwd.margin, idf), bwd, t)
    assert np.allclose(markers[150:170], b[150:170], equal_nan=True)


def test_a_confirmed_rename_does_not_doubt_names_back_past_an_earlier_rename_of_them():
    """A dancer's feet cross and uncross: the forward pass names the legs right up to frame 172,
    renames them wrongly at 173 and back at 178 (a rename the backward pass confirms). The
    backward pass has the legs the other way round from 120 to 172 (its own renames at 172 and
    119). The rename at 178 doubts only what the rename at 173 named (173-177, taken from the
    backward pass); the names before 173 are the forward pass's own, right, and stay. Likewise
    the backward rename at 119, which the forward pass confirms, doubts the backward names only
    up to its unconfirmed rename at 172, not the right ones after it (005_05 on a fresh body:
    the forward legs right for 1 s were replaced by the backward pass's wrong ones, 86.1 ->
    95.7 % of frames all right)."""
    F = 300
    t = np.arange(F) / FPS
    right = _in_a_row(F)
    legs = [LK, RK, LA, RA]
    swapped = [RK, LK, RA, LA]
    a, b = right.copy(), right.copy()
    a[173:178, legs] = right[173:178, swapped]
    b[120:173, legs] = right[120:173, swapped]
    leg_bits = sum(1 << m for m in legs)
    ren_f, ren_b = np.zeros(F, np.int64), np.zeros(F, np.int64)
    ren_f[[173, 178]] = leg_bits
    ren_b[[172, 119]] = leg_bits
    markers, from_b = choose(PassResult(a, ren_f, np.zeros(F)), PassResult(b, ren_b, np.zeros(F)), t)
    assert np.allclose(markers[:, legs], right[:, legs])
    assert np.array_equal(np.flatnonzero(from_b), np.arange(173, 178))


def test_a_name_picked_up_after_a_gap_gives_way_to_the_backward_track_of_that_point():
    """The high rig's climb (001_14): the body hides both shoulders for 20 frames (140-159); when
    the right one comes back, the forward pass names it the left shoulder (its prediction drifted)
    and leaves the right one unnamed until frame 230, with no rename. The backward pass came
    into that stretch tracking the right shoulder on the point. The forward name was picked up
    from a stale prediction after a gap, the backward one tracked: the backward names stand.
    Not when the forward pass had named the left shoulder in the frame before (it tracked it
    too), nor when the backward pass picked the right shoulder up after a gap of its own."""
    F = 300
    t = np.arange(F) / FPS
    b = _in_a_row(F)
    b[140:160, [LS, RS]] = np.nan  # both shoulders hidden
    none = np.zeros(F, np.int64)
    a = b.copy()
    a[160:230, LS] = b[160:230, RS]
    a[160:230, RS] = np.nan
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    assert from_b[160:230].all() and np.allclose(markers[160:230], b[160:230])
    assert np.allclose(markers[230:], a[230:]) and np.allclose(markers[:140], a[:140])

    tracked = a.copy()
    tracked[150:160, LS] = b[0, LS] - [0.0, 0.0, 0.3]  # the forward pass named it through the gap
    markers, _b = choose(PassResult(tracked, none, np.zeros(F)), PassResult(b, none, np.zeros(F)), t)
    # (the backward right shoulder fills the forward gap in it, so the point is disputed: neither name)
    assert np.isnan(markers[160:230, LS]).all()
    gap_b = b.copy()
    gap_b[230:240, RS] = np.nan  # the backward pass came into the stretch without the right shoulder
    markers, from_b = choose(PassResult(a, none, np.zeros(F)), PassResult(gap_b, none, np.zeros(F)), t)
    assert not from_b[160:230].any() and np.allclose(markers[160:230], a[160:230], equal_nan=True)


def test_a_coin_flip_settled_by_the_two_passes_agreeing_no_longer_gives_way():
    """The forward pass identifies the subject after a blackout with a margin of 0 but names it
    right: the two passes agree as a whole from frame 131 to 200. From frame 250 the backward
    pass, tracking from a clear identification at the end, holds a wrist and a knee the other
    way round (a hand at the knee). The forward names stay there: the coin flip was settled
    when the two passes agreed, and what differs later is a slip of the backward pass's own.
    Where the passes never agreed after the coin flip, the backward names win (as above)."""
    from samba_server.both_ways import CLEAR_M

    F = 301
    t = np.arange(F) / FPS
    right = np.arange(8 * 3, dtype=float).reshape(8, 3) / 10.0
    a = np.repeat(right[None], F, axis=0)
    b = a.copy()
    b[250:, [RW, LK]] = right[[LK, RW]]
    a[100:130] = b[100:130] = np.nan
    idf, idb = np.full(F, np.nan), np.full(F, np.nan)
    idf[0], idf[130], idb[300] = 0.0, 0.0, CLEAR_M
    fwd = PassResult(a, np.zeros(F, np.int64), np.zeros(F), idf)
    bwd = PassResult(b, np.zeros(F, np.int64), np.zeros(F), idb)
    markers, from_b = choose(fwd, bwd, t)
    assert not from_b.any() and np.allclose(markers[131:], right)
    b[131:, :, 2] += 0.05  # the passes never agree after the coin flip: the backward names win
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, F))


def test_an_audit_that_kept_the_shoulders_does_not_settle_a_coin_flip():
    """After a blackout the forward pass names the subject the mirror way round (a coin-flip
    identification, margin 0); at frame 200 an audit, which counts agreeing with the tracked
    names as evidence, moves only the right wrist, with a clear margin. The frames after it
    still descend from the coin flip (swordplay on another body: the last 0.4 s of the take
    kept the mirror names): the backward names, from a clear identification, win to the end.
    An identification at 200 that renamed the shoulders starts a clear lineage of its own."""
    from samba_server.both_ways import CLEAR_M

    F = 301
    t = np.arange(F) / FPS
    right = np.arange(8 * 3, dtype=float).reshape(8, 3) / 10.0
    a = np.repeat(right[None], F, axis=0)
    a[131:] = right[MIRROR]
    b = np.repeat(right[None], F, axis=0)
    a[100:130] = b[100:130] = np.nan
    a[200:, RW] += 0.05  # the audit gave the right wrist another point
    idf, idb = np.full(F, np.nan), np.full(F, np.nan)
    idf[0], idf[130], idf[200], idb[300] = 0.0, 0.0, CLEAR_M + 0.002, CLEAR_M
    ren_f = np.zeros(F, np.int64)
    ren_f[200] = 1 << RW
    fwd = PassResult(a, ren_f, np.zeros(F), idf)
    bwd = PassResult(b, np.zeros(F, np.int64), np.zeros(F), idb)
    markers, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, F)) and np.allclose(markers[131:], right)
    ren_f[200] = (1 << RW) | (1 << LS) | (1 << RS)  # a fresh look that renamed the shoulders
    _m, from_b = choose(fwd, bwd, t)
    assert np.array_equal(np.flatnonzero(from_b), np.arange(131, 200))


def test_the_final_solve_weighs_each_chosen_marker_as_the_pass_that_named_it_said():
    """A chosen name keeps the loose flag (position from merged blobs) of the pass that named the
    marker at that point: the forward pass's where both did, the backward pass's where only
    its name was taken; unnamed markers are not loose."""
    rng = np.random.default_rng(1)
    a = rng.normal(0.0, 1.0, (3, 8, 3))
    b = a.copy()
    b[1, LW] += 0.3  # the backward pass names the left wrist elsewhere in frame 1
    loose_f = np.zeros((3, 8), bool)
    loose_f[:, LW] = True  # the forward pass found its left wrist point only in merged blobs
    loose_b = np.zeros((3, 8), bool)
    loose_b[:, RK] = True
    fwd = PassResult(a, np.zeros(3, np.int64), np.zeros(3), None, loose_f)
    bwd = PassResult(b, np.zeros(3, np.int64), np.zeros(3), None, loose_b)
    chosen = a.copy()
    chosen[1, LW] = b[1, LW]  # taken from the backward pass
    chosen[2, LA] = np.nan
    got = loose_of(chosen, fwd, bwd)
    assert got[[0, 2], LW].all() and not got[1, LW]
    assert not got[:, RK].any()  # both passes name it there: the forward pass's word
    assert not got[2, LA]
    assert loose_of(chosen, PassResult(a, fwd.renamed, fwd.margin), PassResult(b, bwd.renamed, bwd.margin)) is None


def test_legs_one_pass_is_sure_of_are_sure_where_the_other_names_them_alike():
    """The forward pass re-identified the legs after a blackout in a lunge (unsure); the
    backward pass tracked them from the take's end, where the knees stood apart (sure). Where
    both name the legs alike, the backward pass's track vouches for the names; where they name
    them differently the chosen pass's doubt stands; unnamed legs are never unsure."""
    rng = np.random.default_rng(2)
    F = 4
    a = rng.normal(0.0, 1.0, (F, 8, 3))
    b = a.copy()
    b[1, [LK, RK, LA, RA]] = a[1, [RK, LK, RA, LA]]  # frame 1: the backward pass named the legs mirrored
    fwd = PassResult(a, np.zeros(F, np.int64), np.zeros(F), legs_unsure=np.ones(F, bool))
    bwd = PassResult(b, np.zeros(F, np.int64), np.zeros(F), legs_unsure=np.array([False, False, True, True]))
    chosen = a.copy()
    chosen[3, [LK, RK, LA, RA]] = np.nan
    got = legs_unsure_of(chosen, fwd, bwd)
    assert list(got) == [False, True, True, False]
    chosen[1] = b[1]  # the backward pass's names chosen there: its word
    assert not legs_unsure_of(chosen, fwd, bwd)[1]
    assert not legs_unsure_of(chosen, PassResult(a, fwd.renamed, fwd.margin), PassResult(b, bwd.renamed, bwd.margin)).any()
