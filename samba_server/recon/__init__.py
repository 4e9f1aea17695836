"""Reconstruction: 8 labelled markers -> the 13-joint skeleton, one code path live and offline.

Modules, in data-path order: :mod:`.db` (motion database), :mod:`.proportions` (subject bone
lengths from the standard pose), :mod:`.kdtree` and :mod:`.kernels` (numba KD-tree search,
pseudo-poses, local prior, Levenberg–Marquardt), :mod:`.reconstruct` (:class:`Reconstructor`
per frame, :func:`reconstruct_take` for a whole take), :mod:`.evaluate` (benchmark and test
helpers). CLIs: ``samba-db`` and ``samba-reconstruct`` (:mod:`samba_server.cli`).
"""

from .db import MotionDB, build_db, default_db_path, load_default_db, sample_path
from .proportions import ProportionError, estimate_lengths
from .reconstruct import PoseResult, ReconstructConfig, Reconstructor, reconstruct_take

__all__ = ["MotionDB", "PoseResult", "ProportionError", "ReconstructConfig", "Reconstructor", "build_db",
           "default_db_path", "estimate_lengths", "load_default_db", "reconstruct_take", "sample_path"]
