import subprocess
import sys

import numpy as np

from samba_common.formats import load_joints, save_markers
from samba_server.cli.reconstruct import main
from samba_server.recon.db import sample_path


def test_reconstruct_sample_take_writes_joints_and_csv(tmp_path, capsys):
    out, csv = tmp_path / "j.npz", tmp_path / "j.csv"
    assert main([str(sample_path()), "--out", str(out), "--csv", str(csv), "--k", "8", "--pseudo", "4"]) == 0
    take = load_joints(out)
    n = len(np.load(sample_path())["t"])
    assert take.joints.shape == (n, 13, 3) and np.isfinite(take.joints).all()
    assert take.extra["bone_lengths"].shape == (8,)
    assert take.extra["joint_bound"].shape == (n, 13) and (take.extra["joint_bound"] > 0).all()
    lines = csv.read_text().splitlines()
    assert len(lines) == n + 1 and lines[0].startswith("t,head_x,head_y,head_z")
    text = capsys.readouterr().out
    assert f"frames {n}" in text and "bone lengths" in text and "ms/frame" in text


def test_bad_inputs_exit_1_with_a_message(tmp_path, capsys):
    assert main([str(tmp_path / "missing.npz"), "--out", str(tmp_path / "o.npz")]) == 1
    assert "not found" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    np.savez(bad, markers=np.zeros((3, 5, 3)), t=np.arange(3.0))
    assert main([str(bad), "--out", str(tmp_path / "o.npz")]) == 1
    assert "[markers]" in capsys.readouterr().err
    empty = tmp_path / "nothing.npz"
    save_markers(empty, np.full((5, 8, 3), np.nan), np.arange(5.0))
    assert main([str(empty), "--out", str(tmp_path / "o.npz")]) == 1
    assert "never seen" in capsys.readouterr().err
    assert not (tmp_path / "o.npz").exists()


def test_console_script_help():
    r = subprocess.run([sys.executable, "-m", "samba_server.cli.reconstruct", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "--pseudo" in r.stdout
    r = subprocess.run([sys.executable, "-m", "samba_server.cli.reconstruct"], capture_output=True, text=True)
    assert r.returncode == 2
