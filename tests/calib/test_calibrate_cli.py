"""samba-calibrate end to end on files: simulate -> extrinsics (+floor) -> self / intrinsics; take readers."""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.calib import Camera, CameraRig, default_rig
from samba_server.cli.calibrate import main
from samba_server.calibrate.intrinsics import Board, BoardError, calibrate_intrinsics, render_board_views
from samba_server.calibrate.simwand import pose_errors, simulate_wand
from samba_server.calibrate.takeio import TakeError, read_take


def test_simulate_extrinsics_with_floor_npz(tmp_path, capsys) -> None:
    wand, lf = tmp_path / "wand", tmp_path / "lf"
    assert main(["simulate", "wand", "--out", str(wand), "--frames", "500", "--fps", "10", "--seed", "3"]) == 0
    assert main(["simulate", "lframe", "--out", str(lf), "--frames", "120", "--lframe", "0.5x0.7"]) == 0
    true = CameraRig.load(wand / "calibration_true.toml")
    # intrinsics-only starting file
    CameraRig([Camera(c.name, c.size, c.matrix, c.dist) for c in true.cameras]).save(tmp_path / "intr.toml")
    out = tmp_path / "calibration.toml"
    rc = main(["extrinsics", str(wand / "take.npz"), "--wand", "0.5", "--calib", str(tmp_path / "intr.toml"),
               "--out", str(out), "--floor", str(lf / "take.npz"), "--lframe", "0.5x0.7"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "wand length: mean" in text and "cam0-cam1" in text and "reprojection rms" in text
    got = CameraRig.load(out)
    assert got.names == true.names
    ce, re = pose_errors(got, true, mode="absolute")  # includes the L-frame floor
    assert ce.max() < 0.03 and re.max() < 0.3
    np.testing.assert_array_equal(got.camera("cam1").matrix, true.camera("cam1").matrix)


def test_extrinsics_from_rendered_videos(tmp_path) -> None:
    """Rendered wand videos go through the mote detector (unlabelled) into the calibration."""
    take = tmp_path / "take"
    assert main(["simulate", "wand", "--out", str(take), "--frames", "250", "--fps", "10", "--videos", "--seed", "1"]) == 0
    assert sorted(p.name for p in take.glob("*.avi")) == ["cam0.avi", "cam1.avi", "cam2.avi", "cam3.avi"]
    out = tmp_path / "cal.toml"
    assert main(["extrinsics", str(take), "--wand", "0.5", "--calib", str(take / "calibration_true.toml"),
                 "--out", str(out)]) == 0
    ce, re = pose_errors(CameraRig.load(out), CameraRig.load(take / "calibration_true.toml"))
    assert ce.max() < 0.03 and re.max() < 0.3


def test_take_from_mcap_recording(tmp_path) -> None:
    from samba_common.wire import UNLABELLED, MarkerPacket, encode_packet
    from samba_server.record import Recorder

    rig = default_rig(2)
    obs = simulate_wand(rig, 50, 0.5, seed=5, fps=10.0)
    path = tmp_path / "wand.mcap"
    period = 100_000_000
    with Recorder(path) as rec:
        for f in range(50):
            for c, name in enumerate(rig.names):
                uv = obs.uv[f, c]
                ok = np.all(np.isfinite(uv), axis=1)
                p = MarkerPacket(name, f, 10**18 + f * period + c * 1_000_000, 160, 120, 128,
                                 np.full(ok.sum(), UNLABELLED, np.uint8), uv[ok].astype(np.float32),
                                 np.full(ok.sum(), 9, np.uint16), np.zeros(ok.sum(), np.uint8))
                rec.write_packet(name, encode_packet(p), 10**18 + f * period + 5_000_000, p.t_ns)
        rec.write_packet("camX", b"garbage", 10**18, 0)
    got = read_take(path, rig.names, 2)
    assert got.shape == (50, 2, 2, 2)
    np.testing.assert_allclose(got, obs.uv, atol=1e-4)  # float32 on the wire
    with pytest.raises(TakeError, match="no marker packets"):
        read_take(path, ["nobody"], 2)


def test_intrinsics_from_board_images_updates_existing_file(tmp_path, capsys) -> None:
    import cv2

    cam = Camera("cam1", (320, 240), [[280.0, 0, 161.0], [0, 280.0, 118.5], [0, 0, 1]], [-0.08, 0.01, 0, 0, 0])
    board = Board.parse("checkerboard:7x5:0.03")
    d = tmp_path / "imgs"
    d.mkdir()
    for i, img in enumerate(render_board_views(cam, board, 12, seed=1)):
        cv2.imwrite(str(d / f"b{i:02d}.png"), img)
    res = calibrate_intrinsics("cam1", d, board)
    assert res.rms_px < 0.3 and res.n_views >= 8
    assert abs(res.camera.matrix[0, 0] / 280.0 - 1) < 0.01 and abs(res.camera.matrix[0, 2] - 161.0) < 1.5
    assert abs(res.camera.dist[0] + 0.08) < 0.01
    # CLI: update cam1 of an existing 2-camera file, keep cam0 and cam1's pose
    rig = default_rig(2)
    rig.save(tmp_path / "calibration.toml")
    rc = main(["intrinsics", str(d), "--camera", "cam1", "--board", "checkerboard:7x5:0.03",
               "--out", str(tmp_path / "calibration.toml")])
    assert rc == 0
    assert "coverage" in capsys.readouterr().out
    got = CameraRig.load(tmp_path / "calibration.toml")
    assert got.names == ["cam0", "cam1"]
    assert np.array_equal(got.camera("cam0").matrix, rig.camera("cam0").matrix)
    assert np.array_equal(got.camera("cam1").tvec, rig.camera("cam1").tvec)
    assert got.camera("cam1").size == (320, 240) and abs(got.camera("cam1").matrix[0, 0] - 280) < 3
    # too few views -> runtime error, exit 1
    one = tmp_path / "one"
    one.mkdir()
    cv2.imwrite(str(one / "x.png"), np.zeros((240, 320), np.uint8))
    assert main(["intrinsics", str(one), "--camera", "cam1", "--board", "checkerboard:7x5:0.03",
                 "--out", str(tmp_path / "c2.toml")]) == 1


def test_board_parsing() -> None:
    assert Board.parse("checkerboard:9x6:0.025") == Board("checkerboard", 9, 6, 0.025)
    b = Board.parse("charuco:5x7:0.04:0.03")
    assert b.kind == "charuco" and b.marker == 0.03 and b.dictionary == "DICT_4X4_50"
    for bad in ["checkerboard:9:0.025", "chess:9x6:0.1", "charuco:5x7:0.04:0.05", "checkerboard:9x6:-1",
                "charuco:5x7:0.04:0.03:DICT_NOPE"]:
        with pytest.raises(BoardError):
            Board.parse(bad)


def test_cli_errors_and_exit_codes(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as ei:
        main(["extrinsics"])
    assert ei.value.code == 2
    default_rig(2).save(tmp_path / "c.toml")
    assert main(["extrinsics", str(tmp_path / "missing.npz"), "--wand", "0.5", "--calib", str(tmp_path / "c.toml"),
                 "--out", str(tmp_path / "o.toml")]) == 1
    assert "not found" in capsys.readouterr().err
    assert main(["intrinsics", str(tmp_path), "--camera", "cam0", "--board", "bad", "--out", str(tmp_path / "o.toml")]) == 2
    (tmp_path / "broken.toml").write_text("[cam_0]\nname = 'a'\n")
    assert main(["self", str(tmp_path / "x.npz"), "--calib", str(tmp_path / "broken.toml"), "--tibia", "0.4"]) == 1
    assert "cam_0.size" in capsys.readouterr().err
    assert not (tmp_path / "o.toml").exists()


def test_self_cli_on_simulated_subject(tmp_path, capsys) -> None:
    sub = tmp_path / "subject"
    assert main(["simulate", "subject", "--out", str(sub), "--seconds", "5", "--seed", "2"]) == 0
    true = CameraRig.load(sub / "calibration_true.toml")
    CameraRig([Camera(c.name, c.size, c.matrix, c.dist) for c in true.cameras]).save(tmp_path / "intr.toml")
    with np.load(sub / "take.npz") as z:
        pts = z["points"]
    tibia = float(np.median(np.linalg.norm(pts[:, 4] - pts[:, 6], axis=1)))
    assert main(["self", str(sub / "take.npz"), "--calib", str(tmp_path / "intr.toml"), "--tibia", f"{tibia:.4f}",
                 "--out", str(tmp_path / "self.toml")]) == 0
    ce, re = pose_errors(CameraRig.load(tmp_path / "self.toml"), true)
    assert ce.max() < 0.03 and re.max() < 0.3
