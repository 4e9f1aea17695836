"""The server CLIs on real files: samba-inspect, samba-replay --out, samba-server errors."""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.formats import load_joints
from samba_common.wire import encode_packet
from samba_server.cli import inspect as inspect_cli
from samba_server.cli import replay
from samba_server.cli import server as server_cli
from samba_server.record import Recorder
from samba_server.simmotes import make_packet, project_take

from .conftest import short_take


@pytest.fixture
def take(tmp_path):
    joints, _ = short_take(seconds=0.2)
    joints = joints[::2][:60]  # 30 fps, 2 s
    rig = default_rig(2)
    uv, vis = project_take(rig, joints)
    rng = np.random.default_rng(0)
    path = tmp_path / "take.mcap"
    with Recorder(path, calibration_toml=rig.dumps().encode()) as rec:
        for k in range(len(joints)):
            for c, name in enumerate(rig.names):
                if k == 10 and c == 1:
                    continue  # one packet lost before recording: a seq gap
                t = 1_000_000_000 + k * 33_333_333
                pkt = make_packet(name, k, t, uv[c, k], vis[c, k], (160, 120), rng, 0.05)
                rec.write_packet(name, encode_packet(pkt), t + 500_000 + c * 100_000)
        rec.write_packet("cam0", b"garbage", 3_000_000_000)
    return path, joints


def test_inspect_reports_and_exports(take, tmp_path, capsys):
    path, joints = take
    n = len(joints)
    out, csv = tmp_path / "j.npz", tmp_path / "j.csv"
    assert inspect_cli.main([str(path), "--export", str(out), "--csv", str(csv)]) == 0
    text = capsys.readouterr().out
    assert f"mote cam0: {n + 1} packets" in text and "1 undecodable" in text
    assert f"mote cam1: {n - 1} packets" in text and "1 lost" in text
    assert load_joints(out).joints.shape == (0, 13, 3)  # no poses in this take
    assert csv.read_text().startswith("t,head_x")
    assert inspect_cli.main([str(tmp_path / "missing.mcap")]) == 1


def test_replay_out_runs_the_server_pipeline(take, tmp_path, caplog):
    path, joints = take
    out = tmp_path / "replayed.npz"
    with caplog.at_level("WARNING", logger="samba_server.app"):
        assert replay.main([str(path), "--out", str(out)]) == 0
    # two cameras: the user is told what their names are worth
    assert any("2 camera(s) in the calibration" in r.getMessage() and "use 3 or more" in r.getMessage()
               for r in caplog.records)
    got = load_joints(out)
    assert len(got.t) == len(joints)  # one frame per capture, the garbage packet dropped
    markers = got.extra["markers"]
    from samba_common.skeleton import MARKER_JOINT

    err = np.linalg.norm(markers - joints[:, list(MARKER_JOINT)], axis=2)
    assert np.nanmedian(err) < 0.01


def test_server_cli_errors(tmp_path, capsys):
    assert server_cli.main(["--calibration", str(tmp_path / "none.toml"), "--duration", "0.1"]) == 1
    assert "samba-server" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        server_cli.main([])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        replay.main([str(tmp_path / "x.mcap"), "--speed", "fast"])
    assert exc.value.code == 2


def test_viewer_record_buttons_start_and_stop_a_readable_recording(tmp_path):
    from samba_common.calib import default_rig
    from samba_server.record import TakeReader
    from samba_server.server import Server
    from samba_server.app import record_toggle

    server = Server(default_rig(2))
    toggle = record_toggle(server, tmp_path)
    toggle(True)
    assert server.recorder is not None
    first = server.recorder
    toggle(True)                      # a second start keeps the running recording
    assert server.recorder is first
    toggle(False)
    assert server.recorder is None
    takes = list(tmp_path.glob("take-*.mcap"))
    assert len(takes) == 1
    assert any(m.topic == "/calibration" or "calib" in m.topic for m in TakeReader(takes[0]))
    toggle(False)                     # stopping when nothing records is harmless


def test_only_a_rig_of_fewer_than_three_cameras_is_warned_about(caplog):
    from samba_server.app import warn_few_cameras

    with caplog.at_level("WARNING", logger="samba_server.app"):
        assert not warn_few_cameras(default_rig(4)) and not caplog.records
        assert warn_few_cameras(default_rig(2)) and "use 3 or more cameras" in caplog.records[0].getMessage()
