"""Test takes and accuracy metrics shared by the tests and the benchmarks.

- :func:`vary_body`: re-pose a take on a body unlike the database's (global scale and
  per-bone-type factors, both sides alike);
- :func:`observe`: markers from joints with noise and randomly missing markers;
- :func:`mpjpe` / :func:`bone_report`: errors normalised to a 45 cm tibia, as the thesis does.
"""

from __future__ import annotations

import numpy as np

from samba_common.body import L, bone_lengths, decompose, fk
from samba_common.skeleton import BONE_TYPES, MARKER_JOINT

TIBIA = 0.45


def vary_body(joints: np.ndarray, rng: np.random.Generator, global_range: float = 0.15,
              bone_range: float = 0.07, scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Re-pose (F, 13, 3) joints with new bone lengths; returns (joints, lengths (8,)).

    The whole skeleton is scaled by a factor in [1 - global_range, 1 + global_range] (or by
    ``scale``: the same draws otherwise, so the same body at another size) and each bone type by
    a further factor in [1 - bone_range, 1 + bone_range]; joint directions and the horizontal
    shoulder trajectory are kept, the height follows the new legs.
    """
    base = np.median(bone_lengths(joints), axis=0)
    g = rng.uniform(1 - global_range, 1 + global_range)
    g = g if scale is None else scale
    lengths = base * g * rng.uniform(1 - bone_range, 1 + bone_range, size=len(BONE_TYPES))
    origin, R, dirs = decompose(joints)
    out = fk(origin * np.array([g, g, 1.0]), R, dirs, lengths)
    low = np.nanpercentile(np.minimum(out[:, 11, 2], out[:, 12, 2]), 2)
    ref = np.nanpercentile(np.minimum(joints[:, 11, 2], joints[:, 12, 2]), 2)
    out[..., 2] += ref - low
    return out, lengths


def observe(joints: np.ndarray, rng: np.random.Generator, noise: float = 0.003, missing: float = 0.05) -> np.ndarray:
    """Markers (F, 8, 3) from joints (F, 13, 3): Gaussian noise (m) and a fraction of NaN markers."""
    m = joints[:, list(MARKER_JOINT)] + rng.normal(0.0, noise, (len(joints), 8, 3))
    m[rng.random((len(joints), 8)) < missing] = np.nan
    return m


def mpjpe(est: np.ndarray, truth: np.ndarray, joints: list[int] | tuple[int, ...] | None = None) -> float:
    """Mean per-joint position error (m), normalised so the true tibia is 45 cm; NaN frames skipped."""
    sel = list(range(truth.shape[1])) if joints is None else list(joints)
    err = np.linalg.norm(est[:, sel] - truth[:, sel], axis=-1)
    norm = TIBIA / np.median(bone_lengths(truth)[:, L["shin"]])
    return float(np.nanmean(err) * norm)


def bone_report(est: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Per bone type (8,), normalised to a 45 cm tibia, metres: ``sigma`` (std of the estimated
    length over the take) and ``mean_error`` (|mean estimated length - true length|)."""
    norm = TIBIA / np.median(bone_lengths(truth)[:, L["shin"]])
    ok = np.all(np.isfinite(est), axis=(1, 2))
    le = bone_lengths(est[ok])
    lt = np.median(bone_lengths(truth), axis=0)
    return {"sigma": le.std(axis=0) * norm, "mean_error": np.abs(le.mean(axis=0) - lt) * norm}
