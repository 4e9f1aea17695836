"""C3D (read back through ezc3d), TRC (OpenSim layout) and CSV exports on real files."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from samba_common.skeleton import J, JOINT_NAMES, MARKER_JOINT, MARKER_NAMES
from samba_server.export.c3d import write_c3d
from samba_server.export.csvfile import write_csv
from samba_server.export.take import ExportTake
from samba_server.export.trc import write_trc


@pytest.fixture
def take(walk):
    joints, t = walk
    joints = joints.copy()
    joints[10] = np.nan  # an unsolved frame
    rng = np.random.default_rng(1)
    markers = joints[:, list(MARKER_JOINT)] + rng.normal(0, 0.003, (len(t), 8, 3))
    markers[20:25, 2] = np.nan  # left wrist unseen
    return ExportTake(joints, t, markers, "walk/joints.npz")


def test_c3d_round_trip(tmp_path, take):
    ezc3d = pytest.importorskip("ezc3d")
    out = tmp_path / "take.c3d"
    assert write_c3d(out, take) == 21
    c = ezc3d.c3d(str(out))
    labels = c["parameters"]["POINT"]["LABELS"]["value"]
    assert labels == list(JOINT_NAMES) + [f"{m}_marker" for m in MARKER_NAMES]
    assert c["parameters"]["POINT"]["UNITS"]["value"] == ["mm"]
    assert c["parameters"]["POINT"]["RATE"]["value"][0] == pytest.approx(60.0)
    pts = c["data"]["points"]  # (4, P, F) mm
    assert pts.shape == (4, 21, 120)
    back = np.transpose(pts[:3], (2, 1, 0)) / 1000.0
    np.testing.assert_allclose(back[:, :13], take.joints, atol=1e-5, equal_nan=True)
    np.testing.assert_allclose(back[:, 13:], take.markers, atol=1e-5, equal_nan=True)
    res = c["data"]["meta_points"]["residuals"][0]
    assert np.all(res[:13, 10] == -1) and np.all(res[15, 20:25] == -1)
    assert np.sum(res == -1) == 13 + 8 + 5  # frame 10 (13 joints + 8 markers) + wrist gap
    t0 = c["parameters"]["SAMBA"]["T0"]["value"][0]
    rate = c["parameters"]["POINT"]["RATE"]["value"][0]
    np.testing.assert_allclose(t0 + np.arange(120) / rate, take.t, atol=1e-6)


def test_trc_layout_and_values(tmp_path, take):
    out = tmp_path / "take.trc"
    write_trc(out, take)
    lines = out.read_text().split("\n")
    assert lines[0].split("\t") == ["PathFileType", "4", "(X/Y/Z)", "take.trc"]
    head = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    assert head["Units"] == "mm" and head["NumFrames"] == "120" and head["NumMarkers"] == "21"
    assert float(head["DataRate"]) == pytest.approx(60.0)
    names = lines[3].split("\t")
    assert names[:3] == ["Frame#", "Time", "head"] and names[5] == "left_shoulder"
    assert lines[4].split("\t")[2:5] == ["X1", "Y1", "Z1"] and lines[5] == ""
    rows = [ln.split("\t") for ln in lines[6:] if ln]
    assert len(rows) == 120 and all(len(r) == 2 + 63 for r in rows)
    r0 = rows[0]
    assert r0[0] == "1" and float(r0[1]) == pytest.approx(0.0)
    head0 = [float(v) for v in r0[2:5]]
    x, y, z = take.joints[0, J["head"]]
    # OpenSim: X forward (= Samba +Y), Y up (= Samba Z), Z right (= Samba +X), millimetres
    assert head0 == pytest.approx([1000 * y, 1000 * z, 1000 * x], abs=1e-3)
    assert rows[10][2:41] == [""] * 39  # NaN -> empty fields
    wrist_col = 2 + 3 * (13 + 2)
    assert rows[22][wrist_col:wrist_col + 3] == ["", "", ""]


def test_csv_columns_and_values(tmp_path, take):
    out = tmp_path / "take.csv"
    assert write_csv(out, take) == 120
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:4] == ["t", "head_x", "head_y", "head_z"] and len(rows[0]) == 40
    assert rows[0][-1] == "right_ankle_z" and len(rows) == 121
    data = np.genfromtxt(out, delimiter=",", skip_header=1)
    np.testing.assert_allclose(data[:, 0], take.t, atol=1e-6)
    np.testing.assert_allclose(data[:, 1:].reshape(120, 13, 3), take.joints, atol=1e-6, equal_nan=True)
    assert rows[11][1] == ""  # unsolved frame: empty fields
