"""Where the shared CMU BVH clips are, for the tests that need them.

``SAMBA_CMU_DIR`` (environment) first, else ``../shared/data/cmu-bvh`` next to the repository.
Tests that need a clip skip with :data:`CMU_SKIP` as the reason, which says where they looked.
"""

from __future__ import annotations

import os
from pathlib import Path

_REPO = Path(__file__).resolve().parents[1]
_CANDIDATES = ([Path(os.environ["SAMBA_CMU_DIR"]).expanduser()] if os.environ.get("SAMBA_CMU_DIR") else []) + \
    [_REPO.parent / "shared" / "data" / "cmu-bvh"]

#: the clips folder (may not exist: check ``CMU_DIR.is_dir()`` or use the ``cmu_dir`` fixture)
CMU_DIR: Path = next((p for p in _CANDIDATES if p.is_dir()), _CANDIDATES[0])
#: skip reason naming where the clips were looked for and how to point at them
CMU_SKIP = (f"shared CMU clips not found (looked in {', '.join(str(p) for p in _CANDIDATES)}); "
            "set SAMBA_CMU_DIR to the folder of the CMU .bvh files")
