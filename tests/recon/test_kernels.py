"""The compiled pieces of the solver: KD-tree search, pseudo-poses, prior, LM."""

from pathlib import Path

import numpy as np

from samba_common.body import D, fk, standard_dirs
from samba_common.config import load_section
from samba_server.recon import kernels
from samba_server.recon.kdtree import KDTree
from samba_server.recon.reconstruct import ReconstructConfig

LENGTHS = np.array([0.37, 0.19, 0.5, 0.14, 0.25, 0.26, 0.47, 0.45])


def test_kdtree_matches_brute_force():
    rng = np.random.default_rng(0)
    for dim in (3, 12):
        pts = rng.normal(size=(3000, dim))
        tree = KDTree.build(pts)
        for q in rng.normal(size=(50, dim)):
            want = np.argsort(np.sum((pts - q) ** 2, axis=1))[:10]
            np.testing.assert_array_equal(tree.query(q, 10), want)
    assert list(KDTree.build(pts[:3]).query(pts[1], 10)) == [1, *np.argsort(np.sum((pts[:3] - pts[1]) ** 2, 1))[1:]]


def _pool(n_pseudo, sigma=0.1, seed=0):
    rng = np.random.default_rng(seed)
    db = np.repeat(standard_dirs()[None], 3, axis=0).astype(np.float32)
    db[:, D["left_forearm"]] = (0.0, 1.0, 0.0)  # bent left elbow
    ang = rng.standard_normal((n_pseudo, kernels.N_ANGLES)) * sigma
    out = np.empty((2 * (n_pseudo + 1), 11, 3))
    kernels.pseudo_pool(db, np.array([0, 2]), np.cos(ang), np.sin(ang), out)
    return db, out


def test_pseudo_poses_keep_unit_bones_and_the_neighbours():
    db, pool = _pool(10)
    assert pool.shape == (22, 11, 3)
    np.testing.assert_allclose(np.linalg.norm(pool, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(pool[0], db[0])       # each neighbour first, unchanged
    np.testing.assert_array_equal(pool[11], db[2])
    spread = np.degrees(np.arccos(np.clip(np.sum(pool[1:11] * pool[0], -1), -1, 1)))
    assert 1.0 < spread.mean() < 20.0                     # small joint-angle noise, not chaos
    # the spine only leans in the torso's x-y plane
    np.testing.assert_allclose(pool[:, D["spine"], 2], 0.0, atol=1e-12)


def test_hinge_noise_keeps_the_elbow_a_hinge():
    """With ball noise off, the forearm moves only in the limb plane (about the hinge axis)."""
    rng = np.random.default_rng(1)
    ang = np.zeros((20, kernels.N_ANGLES))
    ang[:, 7] = rng.normal(0, 0.2, 20)  # left-arm hinge only
    db = np.repeat(standard_dirs()[None], 1, axis=0).astype(np.float32)
    db[0, D["left_forearm"]] = (np.sqrt(0.5), np.sqrt(0.5), 0.0)
    out = np.empty((21, 11, 3))
    kernels.pseudo_pool(db, np.array([0]), np.cos(ang), np.sin(ang), out)
    normal = np.cross(db[0, D["left_upper_arm"]], db[0, D["left_forearm"]])
    assert np.abs(out[:, D["left_forearm"]] @ normal).max() < 1e-9
    np.testing.assert_array_equal(out[:, D["left_upper_arm"]], np.repeat(db[:, D["left_upper_arm"]], 21, 0))


def test_lm_recovers_a_pose_from_its_markers():
    """Markers of a known pose, a flat prior around a perturbed start: LM finds the pose."""
    rng = np.random.default_rng(2)
    dirs = standard_dirs()
    dirs[D["left_forearm"]] = (0.6, 0.8, 0.0)
    R = np.eye(3)
    o = np.array([0.1, 0.2, 1.4])
    truth = fk(o, R, dirs, LENGTHS)
    obs = truth[list(kernels.MARKER_JOINTS)]
    mu, W = np.zeros(kernels.N_POSE), np.eye(kernels.N_POSE) * 0.01
    mu[:33] = dirs.reshape(-1)
    start = dirs + rng.normal(0, 0.05, dirs.shape)
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    start[D["spine"], 2] = 0
    start[D["spine"]] /= np.linalg.norm(start[D["spine"]])
    out = kernels.lm_solve(R, o + 0.02, start, LENGTHS, np.zeros((8, 3)), mu, W, np.eye(3), obs, np.ones(8, bool),
                           np.full(8, 0.003), False,
                           np.zeros((13, 3)), 1.0, kernels.G, 50, 1e-12)
    q = out[3]
    assert np.abs(q[list(kernels.MARKER_JOINTS)] - obs).max() < 1e-3
    assert np.abs(q - truth).max() < 0.01


def test_config_file_lists_the_defaults():
    path = Path(__file__).resolve().parents[2] / "configs" / "reconstruct.toml"
    assert load_section(ReconstructConfig, path, "reconstruct") == ReconstructConfig()
