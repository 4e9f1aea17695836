import numpy as np
import pytest

from samba_common.formats import FormatError
from samba_server.cli.db import main as db_main
from samba_server.recon.db import MotionDB, build_db, load_default_db

from ..common.bvh_factory import write_cmu_bvh


def test_build_prunes_mirrors_and_round_trips(tmp_path):
    src = write_cmu_bvh(tmp_path / "walk.bvh", n_frames=120)
    db = build_db([src], fps=30.0, min_change_deg=4.0)
    assert list(db.clip_names) == ["walk", "walk~mirror"]
    n_frames = 60  # 120 frames at 60 fps resampled to 30
    assert 5 < len(db) < 2 * n_frames                          # near-duplicates pruned
    assert np.allclose(np.linalg.norm(db.dirs, axis=-1), 1.0, atol=1e-5)
    db.save(tmp_path / "db.npz")
    back = MotionDB.load(tmp_path / "db.npz")
    np.testing.assert_array_equal(back.dirs, db.dirs)
    z = np.load(tmp_path / "db.npz")
    assert z["markers_aligned"].shape == (len(db), 8, 3) and z["joints_aligned"].shape == (len(db), 13, 3)
    # aligned joints: the shin is 1 and the shoulders sit on the x axis
    sh = np.linalg.norm(z["joints_aligned"][:, 9] - z["joints_aligned"][:, 11], axis=-1)
    assert np.allclose(sh, 1.0, atol=1e-4)


def test_no_pruning_keeps_every_frame(tmp_path):
    src = write_cmu_bvh(tmp_path / "walk.bvh", n_frames=60)
    db = build_db([src], fps=30.0, min_change_deg=0.0, mirror=False)
    assert len(db) == 30


def test_users_can_extend_the_default_db(tmp_path):
    base = load_default_db()
    src = write_cmu_bvh(tmp_path / "mine.bvh")
    out = tmp_path / "mine.npz"
    assert db_main(["build", str(src), "--add-to", "default", "--out", str(out)]) == 0
    db = MotionDB.load(out)
    assert len(db) > len(base) and "mine" in set(db.clip_names)


def test_default_db_is_compact_and_covers_the_shared_clips():
    db = load_default_db()
    names = {n for n in db.clip_names if not n.endswith("~mirror")}
    assert len(names) == 49 and 5_000 < len(db) < 60_000


def test_bad_database_files(tmp_path, capsys):
    p = tmp_path / "x.npz"
    np.savez(p, dirs=np.zeros((3, 11, 3)))
    with pytest.raises(FormatError, match=r"\[version\]"):
        MotionDB.load(p)
    assert db_main(["info", str(p)]) == 1
    assert "version" in capsys.readouterr().err
    assert db_main(["build", str(tmp_path / "empty_dir_that_does_not_exist.bvh"), "--out", str(tmp_path / "o.npz")]) == 1
