"""Read back an exported BVH: the check that an exported BVH means what it says.

Parsing and forward kinematics are the shared ones of :mod:`samba_common.bvh`;
:func:`fk_positions` maps the joints of :mod:`samba_server.export.bvh` back to the 13 Samba
joints in the Samba world frame.
"""

from __future__ import annotations

import numpy as np

from samba_common.bvh import BvhDocument, forward_kinematics
from samba_common.bvh import BvhError as BvhParseError  # noqa: F401  (re-exported)
from samba_common.bvh import read_bvh as parse_bvh  # noqa: F401  (re-exported)
from samba_common.skeleton import JOINT_NAMES


def fk_positions(bvh: BvhDocument) -> np.ndarray:
    """The 13 Samba joints (F, 13, 3) in world metres (Z up) from a Samba-exported BVH."""
    from .bvh import BVH_TO_SAMBA, TO_BVH

    samba_to_bvh = {v: k for k, v in BVH_TO_SAMBA.items()}
    g = forward_kinematics(bvh)
    try:
        cols = [bvh.index(samba_to_bvh[n]) for n in JOINT_NAMES]
    except KeyError as exc:
        raise BvhParseError(f"not a Samba BVH: no joint {exc}") from None
    return g[:, cols] @ np.linalg.inv(TO_BVH).T
