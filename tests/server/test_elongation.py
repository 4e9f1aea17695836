"""Two markers in one blob: the mote measures the blob's second moments, the packet carries them,
the server places the two markers from them (feet at hip width: knees and ankles merge)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.skeleton import BONE_TYPES, MARKER_JOINT
from samba_common.wire import UNLABELLED, MarkerPacket, decode_packet, encode_packet
from samba_mote.detect import DetectConfig, Detector
from samba_mote.pipeline import MotePipeline
from samba_mote.sim.motion import DEFAULT_LENGTHS
from samba_mote.sim.tpose import stance_offset, tpose
from samba_mote.sim.render import SimConfig, render_frame
from samba_server.labelling import Labeller
from samba_server.labelling.labeller import LabelConfig
from samba_server.labelling.elongation import blob_separation, jacobians, separation_3d
from samba_server.labelling.rigid import LA, LK, LW, RA, RK, RW
from samba_server.recon.proportions import estimate_lengths

FPS = 60.0


def test_a_merged_blobs_moments_measure_its_two_markers_separation():
    """Rendered markers (radius 1.5 px, sensor noise) 2.5-4 px apart mostly make one blob; its
    moments give their separation vector, up to its sign, to 0.2 px (median; 90 % within 0.5 px)."""
    rng = np.random.default_rng(1)
    det = Detector(DetectConfig(static_mask=False))
    cfg = SimConfig(noise_sigma=2.0, n_distractors=0, hot_pixels=0)
    det.detect(render_frame((160, 120), np.array([[50.0, 50.0]]), np.ones(1), np.ones(1, bool), None, cfg, rng))
    errors = []
    for _ in range(60):
        a = rng.uniform(30, 130, 2)
        s = rng.uniform(2.5, 4.0) * np.array([np.cos(th := rng.uniform(0, np.pi)), np.sin(th)])
        img = render_frame((160, 120), np.stack([a, a + s]), np.full(2, 1.5), np.ones(2, bool), None, cfg, rng)
        d = det.detect(img)
        if len(d) != 1:
            continue  # far enough apart (diagonally) to be two blobs
        est = blob_separation(d.cov)[0]
        errors.append(min(np.linalg.norm(est - s), np.linalg.norm(est + s)))
    assert len(errors) >= 30
    assert np.median(errors) < 0.2 and np.mean(np.array(errors) < 0.5) >= 0.9, np.round(errors, 2)


def test_the_packet_carries_each_blobs_moments():
    """Mote pipeline -> wire -> server: a measured record carries its blob's moments (px^2)."""
    cfg = SimConfig(noise_sigma=2.0, n_distractors=0, hot_pixels=0)
    uv = np.array([[40.0, 30.0], [100.0, 80.0], [103.0, 80.0]])  # one single, two merged
    img = render_frame((160, 120), uv, np.full(3, 1.5), np.ones(3, bool), None, cfg, np.random.default_rng(2))
    pkt = decode_packet(encode_packet(MotePipeline(mote_id="cam0").process(1_000, img)))
    measured = pkt.area > 0
    assert measured.sum() == 2 and np.isfinite(pkt.moments[measured]).all()
    sep = np.linalg.norm(blob_separation(pkt.moments[measured]), axis=1)
    merged = np.argmax(pkt.area[measured])
    assert sep[merged] == pytest.approx(3.0, abs=0.4) and sep[1 - merged] < 1.5


def test_separation_in_3d_from_several_views_and_its_sign_from_the_prior():
    """Two markers 14 cm apart seen merged by four cameras (each view's sign unknown): their 3D
    separation to a few mm; the prior, however rough, only chooses the sign."""
    rig = default_rig(4)
    rng = np.random.default_rng(3)
    X = np.array([0.1, -0.2, 0.5])
    S = np.array([0.12, 0.05, -0.05])
    seps = []
    for cam in rig.cameras:
        uv = cam.project(np.stack([X + S / 2, X - S / 2]))
        seps.append((uv[0] - uv[1]) * rng.choice([-1.0, 1.0]) + rng.normal(0, 0.1, 2))
    J = jacobians(lambda P: np.stack([cam.project(P) for cam in rig.cameras]), X)
    got = separation_3d(J, seps, prior=np.array([0.16, 0.0, 0.0]))
    assert np.linalg.norm(got - S) < 0.01
    got = separation_3d(J, seps, prior=np.array([-0.16, 0.0, 0.0]))
    assert np.linalg.norm(got + S) < 0.01
    # one view says nothing along its ray: that part comes from the prior
    one = separation_3d(J[:1], seps[:1], prior=S + np.array([0.0, 0.0, 0.03]))
    ray = rig.cameras[0].center - X
    ray /= np.linalg.norm(ray)
    assert np.linalg.norm((one - S) - ((one - S) @ ray) * ray) < 0.01
    assert separation_3d(J, np.full((4, 2), np.nan), prior=S) is None


def _merging_packets(rig, markers, t, moments=True, radius_px=1.6, merge_px=4.5, hidden=None, small=()):
    """One MarkerPacket per camera as a mote sees the markers (8, 3): two markers projected
    closer than merge_px make one blob at their midpoint, of twice the area, whose second
    moments are a single marker's plus s s^T / 4 (s: their separation, px); unlabelled.
    hidden: {camera index: [markers that camera does not see]}; small: cameras whose merged
    blobs have a single marker's area (the two overlap; only the moments show two)."""
    out = []
    single = radius_px ** 2 / 4.0
    for c, cam in enumerate(rig.cameras):
        uv = cam.project(np.delete(markers, (hidden or {}).get(c, []), axis=0))
        used = np.zeros(len(uv), bool)
        blobs, areas, moms = [], [], []
        for i in range(len(uv)):
            if used[i]:
                continue
            d = np.linalg.norm(uv - uv[i], axis=1)
            d[used | (np.arange(len(uv)) <= i)] = np.inf
            j = int(np.argmin(d))
            if d[j] < merge_px:
                s = uv[i] - uv[j]
                used[[i, j]] = True
                blobs.append(0.5 * (uv[i] + uv[j]))
                areas.append(9 if c in small else 18)
                moms.append([single + s[0] ** 2 / 4, s[0] * s[1] / 4, single + s[1] ** 2 / 4])
            else:
                used[i] = True
                blobs.append(uv[i])
                areas.append(9)
                moms.append([single, 0.0, single])
        n = len(blobs)
        mom = np.array(moms, np.float32) if moments else None
        out.append(MarkerPacket(cam.name, 0, int(t * 1e9), 160, 120, 100, np.full(n, UNLABELLED, np.uint8),
                                np.array(blobs, np.float32), np.array(areas, np.uint16), np.zeros(n, np.uint8), mom))
    return out


@pytest.mark.parametrize("moments", [True, False])
def test_merged_knees_and_ankles_of_a_hip_width_stance_are_placed_from_the_moments(moments):
    """Feet at hip width (20 cm) seen from 5 m: the knees merge in every view, and the ankles
    too, in camera 1 in blobs of a single marker's area (the two overlap there; only the moments
    show two). By default the knees and the ankles are split by the blobs' moments
    (``split_legs_sigma_px``): the four markers within 1.5 cm, and the subject's hip width,
    measured from them, within 1.5 cm. Without moments (a version-1 packet) the split is a
    guess, at most 8 cm either side of the merged point along the subject's right: here 2 cm
    off each, and the hip width 16 cm."""
    rig = default_rig(4)
    hip = float(DEFAULT_LENGTHS[BONE_TYPES.index("hip_width")])
    pose = tpose(DEFAULT_LENGTHS, stance=stance_offset("hip", hip))[list(MARKER_JOINT)]
    lab = Labeller(rig)
    frames = []
    for i in range(30):
        named, _q = lab.label(_merging_packets(rig, pose, i / FPS, moments, small=(1,)), i / FPS)
        frames.append(named)
    err = np.linalg.norm(named[[LK, RK, LA, RA]] - pose[[LK, RK, LA, RA]], axis=1)
    width = estimate_lengths(np.array(frames), DEFAULT_LENGTHS)[BONE_TYPES.index("hip_width")]
    if moments:
        assert (err < 0.015).all(), err
        assert width == pytest.approx(hip, abs=0.015)
    else:
        assert err.min() > 0.015, err
        assert width < hip - 0.03


def test_merged_knees_one_a_little_before_the_other_keep_only_the_split_along_the_subjects_right():
    """Knees at hip width, the left 2 cm before the right (a step), merged in every view (blobs
    merge up to 6 px here). The split takes the 20 cm across the body from the moments but not
    the 4 cm front to back, whose sign no view tells (taken, it swapped a walk's knees): the
    named knees lie 20 cm apart along the subject's right and level front to back, each within
    the 2 cm it cannot know."""
    rig = default_rig(4)
    hip = float(DEFAULT_LENGTHS[BONE_TYPES.index("hip_width")])
    pose = tpose(DEFAULT_LENGTHS, stance=stance_offset("hip", hip))[list(MARKER_JOINT)]
    pose[LK, 1] += 0.02
    pose[RK, 1] -= 0.02
    lab = Labeller(rig)
    for i in range(20):
        packets = _merging_packets(rig, pose, i / FPS, merge_px=6.0)
        named, _q = lab.label(packets, i / FPS)
    assert all(int((p.area == 18).sum()) == 2 for p in packets)  # knees and ankles merged in every view
    sep = named[LK] - named[RK]
    assert sep[0] == pytest.approx(pose[LK, 0] - pose[RK, 0], abs=0.01)
    assert abs(sep[1]) < 0.005
    err = np.linalg.norm(named[[LK, RK]] - pose[[LK, RK]], axis=1)
    assert (err < 0.025).all(), err


def test_a_marker_seen_only_merged_with_another_gets_a_point_on_the_blobs_far_ends():
    """Knees at hip width (a rendered take's lead-in, traced): camera 0 sees only the left knee
    (the right one hidden behind the leg), camera 1 both in one blob of a single marker's size,
    cameras 2 and 3 both in one large blob. The left knee's point (from cameras 0 and 1) takes
    the near end of each large blob; the right knee becomes a point on the far ends. Both are
    named within 1 cm. Before, the left knee's point, its blobs twice a marker's size in half
    its views, was taken for both knees and split either side: both 10 cm off."""
    rig = default_rig(4)
    pose = tpose(DEFAULT_LENGTHS, stance=stance_offset("hip", float(DEFAULT_LENGTHS[1])))[list(MARKER_JOINT)]
    lab = Labeller(rig)
    for i in range(20):
        packets = _merging_packets(rig, pose, i / FPS, hidden={0: [RK]}, small=(1,))
        named, _q = lab.label(packets, i / FPS)
    assert [int((p.area == 18).sum()) for p in packets] == [1, 0, 2, 2]  # merged knees (and ankles)
    err = np.linalg.norm(named[[LK, RK]] - pose[[LK, RK]], axis=1)
    assert (err < 0.01).all(), err


def _hilt_scene():
    """A 4-camera rig, the standard pose at hip width (8, 3) m, a sword hilt in front of the
    belly (3,) m, the unit vector (3,) from the right wrist to the left one in that pose, and
    three static reflections high on the walls (3, 3) m."""
    rig = default_rig(4)
    hip = float(DEFAULT_LENGTHS[BONE_TYPES.index("hip_width")])
    pose = tpose(DEFAULT_LENGTHS, stance=stance_offset("hip", hip))[list(MARKER_JOINT)]
    left = (pose[LW] - pose[RW]) / np.linalg.norm(pose[LW] - pose[RW])
    clutter = np.array([[2.5, 0.0, 2.5], [-2.5, 0.5, 2.4], [0.0, 2.8, 2.6]])
    return rig, pose, np.array([0.0, 0.25, 1.15]), left, clutter


@pytest.mark.parametrize("sigma_px", [0.5, float("inf")])
def test_hands_together_on_a_turning_hilt_are_placed_from_the_moments(sigma_px):
    """Both hands on a sword hilt in front of the belly, 12 cm apart and merged in every view,
    the hilt turned over in 1 s (the hands' separation turning 180 degrees in the vertical
    plane, through one hand above the other). Split by the merged blobs' moments
    (``split_wrists_sigma_px``, the sign from the tracks' separation, which follows the turn
    frame by frame) each wrist stays within 2 cm of its marker all through the turn; split by
    the tracks alone (inf) the wrists lag the turn, 6 cm or more off at some frame of it. Three
    static reflections keep the views' typical blob a single marker's (hands, knees and ankles
    merged: three of the subject's five blobs are two markers' size)."""
    rig, pose, hilt, left, clutter = _hilt_scene()
    lab = Labeller(rig, config=LabelConfig(split_wrists_sigma_px=sigma_px))

    def hands(theta: float) -> np.ndarray:
        return 0.06 * (np.cos(theta) * left + np.sin(theta) * np.array([0.0, 0.0, 1.0]))

    frames = [pose.copy() for _ in range(30)]  # the standard pose
    for s in np.linspace(0.0, 1.0, 31)[1:]:  # hands to the hilt in 0.5 s
        m = pose.copy()
        m[LW] = (1 - s) * pose[LW] + s * (hilt + hands(0.0))
        m[RW] = (1 - s) * pose[RW] + s * (hilt - hands(0.0))
        frames.append(m)
    for theta in np.linspace(0.0, np.pi, 61)[1:]:  # the hilt turned over in 1 s
        m = pose.copy()
        m[LW], m[RW] = hilt + hands(theta), hilt - hands(theta)
        frames.append(m)
    err = []
    for i, m in enumerate(frames):
        packets = _merging_packets(rig, np.vstack([m, clutter]), i / FPS)
        named, _q = lab.label(packets, i / FPS)
        if i >= 60:
            assert all(int((p.area == 18).sum()) == 3 for p in packets)  # hands, knees, ankles merged
            err.append(np.linalg.norm(named[[LW, RW]] - m[[LW, RW]], axis=1))
    err = np.array(err)
    assert np.isfinite(err).all()
    if np.isfinite(sigma_px):
        assert err.max() < 0.02, err.max(axis=0)
    else:
        assert err.max() > 0.06, err.max(axis=0)


def _hilt_take():
    """The hilt scene of the test above, held still: 30 frames of the standard pose, the hands
    brought to the hilt in 0.5 s (12 cm apart, left and right), then held there 1 s, merged in
    every view. Returns the rig, markers (F, 8, 3) and the static clutter (3, 3) m."""
    rig, pose, hilt, left, clutter = _hilt_scene()
    half = 0.06 * left
    frames = [pose.copy() for _ in range(30)]
    for s in np.linspace(0.0, 1.0, 91)[1:]:
        m = pose.copy()
        s = min(1.0, 3.0 * s)
        m[LW] = (1 - s) * pose[LW] + s * (hilt + half)
        m[RW] = (1 - s) * pose[RW] + s * (hilt - half)
        frames.append(m)
    return rig, np.array(frames), clutter


@pytest.mark.parametrize("apart_views", [2, 0])
def test_samba_process_leaves_hands_no_view_separates_unnamed(apart_views):
    """Hands together on a hilt, merged in every view: which wrist is which is a coin flip no
    view can settle (a swordplay had them swapped, 14-16 cm off, for a second). The labelling
    still names both for the solver and the two-way pass (``Labeller.unseparated`` flags them);
    the poses the live server sends and the two-way output of ``samba-process`` leave them
    unnamed, a gap rather than a guess, while every frame is still solved and the wrists' bounds
    cover the other wrist. With ``apart_views = 0`` they are named."""
    from samba_server.both_ways import PassResult, relabel_both_ways
    from samba_server.recon.reconstruct import Reconstructor
    from samba_server.server import Server, ServerConfig
    from samba_common.skeleton import JOINT_NAMES

    rig, frames, clutter = _hilt_take()
    F = len(frames)
    server = Server(rig, None, Reconstructor(lengths=DEFAULT_LENGTHS), ServerConfig(max_lag_ms=0.0),
                    label_config=LabelConfig(apart_views=apart_views))
    t = np.arange(F) / FPS
    packets = [_merging_packets(rig, np.vstack([m, clutter]), float(t[k])) for k, m in enumerate(frames)]
    fwd = PassResult(np.full((F, 8, 3), np.nan), np.zeros(F, np.int64), np.full(F, np.nan),
                     unseparated=np.zeros((F, 8), bool))
    for k in range(F):
        markers, _mask, _q = server.label_packets(packets[k], float(t[k]))
        fwd.markers[k] = server.solve_markers(markers, float(t[k]))[0]
        fwd.unseparated[k] = server.labeller.unseparated(fwd.markers[k])
    held = np.arange(60, F)  # hands on the hilt
    assert all(int((p.area == 18).sum()) == 3 for p in packets[-1])  # hands, knees, ankles merged
    assert np.isfinite(fwd.markers[:30]).all() and np.isfinite(fwd.markers[held]).all()  # the live pass names them
    assert fwd.unseparated[held][:, [LW, RW]].all() == (apart_views == 2)
    assert not fwd.unseparated[:30].any() and not fwd.unseparated[:, [0, 1, 4, 5, 6, 7]].any()
    joints, extra = relabel_both_ways(server, packets, t, fwd)
    out = extra["markers"]
    assert np.isfinite(joints).all()  # every frame solved
    assert np.isfinite(out[:30]).all() and np.isfinite(out[held][:, [0, 1, 4, 5, 6, 7]]).all()
    wrists = [JOINT_NAMES.index("left_wrist"), JOINT_NAMES.index("right_wrist")]
    if apart_views:
        assert np.isnan(out[held][:, [LW, RW]]).all()
        apart = np.linalg.norm(joints[held, wrists[0]] - joints[held, wrists[1]], axis=1)
        assert (extra["joint_bound"][held][:, wrists] >= apart[:, None] - 1e-9).all() and apart.min() > 0.05
    else:
        assert np.isfinite(out[held]).all()
    live = Server(rig, None, Reconstructor(lengths=DEFAULT_LENGTHS), ServerConfig(max_lag_ms=0.0),
                  label_config=LabelConfig(apart_views=apart_views))
    base = 10**12
    for cam in rig.cameras:
        live.mote_event(cam.name, True, base)
    for k, frame in enumerate(packets):
        for pkt in frame:
            live.ingest(pkt.mote_id, encode_packet(replace(pkt, seq=k, t_ns=base + int(t[k] * 1e9))),
                        arrival_ns=base + int(t[k] * 1e9))
        live.process_pending()
    live.finish()
    sent = np.array([p.markers for p in live.poses])
    assert len(sent) == F and all(p.solved for p in live.poses[-len(held):])
    assert np.isnan(sent[held][:, [LW, RW]]).all() == bool(apart_views)
    assert np.isfinite(sent[held][:, [0, 1, 4, 5, 6, 7]]).all()
    assert all((p.marker_mask & 0b1100 == 0) == bool(apart_views) for p in live.poses[-len(held):])
