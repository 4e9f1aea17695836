"""samba-export end to end: a joints.npz on disk to each format, errors and exit codes."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from samba_common.formats import save_joints, save_markers
from samba_common.bvh import read_bvh
from samba_common.skeleton import MARKER_JOINT
from samba_server.cli.export import main
from samba_server.export.bvh import fk_positions


@pytest.fixture
def joints_npz(tmp_path, walk):
    joints, t = walk
    path = tmp_path / "joints.npz"
    save_joints(path, joints, t)
    return path


@pytest.mark.parametrize("fmt", ["bvh", "c3d", "trc", "csv"])
def test_each_format_writes_a_file(tmp_path, joints_npz, fmt):
    out = tmp_path / f"out.{fmt}"
    assert main([str(joints_npz), "--format", fmt, "--out", str(out)]) == 0
    assert out.stat().st_size > 1000
    assert not list(tmp_path.glob("*.part*"))


def test_bvh_from_npz_reproduces_joints(tmp_path, joints_npz, walk):
    out = tmp_path / "take.bvh"
    assert main([str(joints_npz), "--out", str(out)]) == 0  # format from the suffix
    assert np.abs(fk_positions(read_bvh(out)) - walk[0]).max() < 1e-3


def test_markers_option_adds_markers(tmp_path, joints_npz, walk):
    joints, t = walk
    mpath = tmp_path / "markers.npz"
    save_markers(mpath, joints[:, list(MARKER_JOINT)], t)
    out = tmp_path / "take.trc"
    assert main([str(joints_npz), "--markers", str(mpath), "-o", str(out)]) == 0
    assert "left_wrist_marker" in out.read_text().split("\n")[3]


def test_errors_and_exit_codes(tmp_path, joints_npz, capsys):
    assert main([str(tmp_path / "missing.npz"), "-o", str(tmp_path / "a.bvh")]) == 1
    assert "missing.npz" in capsys.readouterr().err
    assert main([str(joints_npz), "-o", str(tmp_path / "a.xyz")]) == 2
    bad = tmp_path / "bad.npz"
    np.savez(bad, joints=np.zeros((3, 12, 3)), t=np.arange(3.0))
    assert main([str(bad), "-o", str(tmp_path / "a.csv")]) == 1
    assert "bad.npz" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["--format", "bvh"])
    assert exc.value.code == 2


def test_console_script_runs(tmp_path, joints_npz):
    out = tmp_path / "take.csv"
    proc = subprocess.run([sys.executable, "-m", "samba_server.cli.export", str(joints_npz), "-o", str(out)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and out.read_text().startswith("t,head_x")
