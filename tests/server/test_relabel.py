"""3D-guided labelling of the blobs the motes left unlabelled."""

import numpy as np

from samba_common.body import standard_pose
from samba_common.calib import default_rig
from samba_common.skeleton import MARKER_JOINT
from samba_common.wire import FLAG_MERGED, FLAG_TRACKED, UNLABELLED, MarkerPacket
from samba_server.relabel import GuidedLabeller, RelabelConfig

LENGTHS = np.array([0.37, 0.19, 0.5, 0.14, 0.25, 0.26, 0.47, 0.45])


def _packet(uv, labels, flags):
    n = len(labels)
    return MarkerPacket("cam0", 0, 0, 160, 120, 128, np.array(labels, np.uint8), np.array(uv, np.float32),
                        np.full(n, 10, np.uint16), np.array(flags, np.uint8))


def test_unlabelled_blobs_near_the_prediction_get_labels():
    rig = default_rig(2)
    joints = standard_pose(LENGTHS)
    lab = GuidedLabeller(rig)
    lab.observe(0.0, joints)
    lab.observe(1 / 30, joints + [0.01, 0, 0])               # moving +x at 0.3 m/s
    truth = joints[list(MARKER_JOINT)] + [0.02, 0, 0]        # where the markers are at t = 2/30
    uv_true = rig.project(truth)                              # (2, 8, 2)
    packets, uv = [], np.full((2, 8, 2), np.nan)
    for c in range(2):
        # the mote labelled only the shoulders; the rest come unlabelled, plus a far distractor
        labels = [0, 1] + [UNLABELLED] * 6 + [UNLABELLED]
        blobs = np.vstack([uv_true[c], [[5.0, 5.0]]])
        packets.append(_packet(blobs, labels, [FLAG_TRACKED] * 9))
        uv[c, :2] = uv_true[c, :2]
    out = lab.fill(uv, packets, 2 / 30)
    np.testing.assert_allclose(out, uv_true, atol=1e-4)
    assert lab.labelled == 12


def test_ambiguous_merged_or_stale_blobs_stay_unlabelled():
    rig = default_rig(2)
    joints = standard_pose(LENGTHS)
    lab = GuidedLabeller(rig, RelabelConfig(gate_px=4.0, ratio=1.5))
    lab.observe(0.0, joints)
    p = rig.project(joints[list(MARKER_JOINT)])[0]
    uv = np.full((2, 8, 2), np.nan)
    # two blobs equally near the left wrist: ambiguous; the right wrist's blob is merged
    blobs = [p[2] + [1.0, 0], p[2] - [1.0, 0], p[3]]
    pk = _packet(blobs, [UNLABELLED] * 3, [FLAG_TRACKED, FLAG_TRACKED, FLAG_TRACKED | FLAG_MERGED])
    out = lab.fill(uv, [pk, None], 0.0)
    assert np.isnan(out[0, 2]).all() and np.isnan(out[0, 3]).all()
    # too old a prediction labels nothing
    pk = _packet([p[2]], [UNLABELLED], [FLAG_TRACKED])
    assert np.isnan(lab.fill(uv, [pk, None], 1.0)).all()
    assert np.isfinite(lab.fill(uv, [pk, None], 0.1)[0, 2]).all()
