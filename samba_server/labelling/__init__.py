"""Marker identification on the server: unlabelled 3D points first, then names.

The data path of one frame (:class:`~samba_server.labelling.labeller.Labeller`):

1. :mod:`.blobs` — every mote's measured blobs (labelled or not), merged blobs marked, the
   motes' labels kept as hints;
2. :mod:`.points` — correspondences across views with epipolar gating on undistorted
   coordinates, candidates triangulated from >= 2 views, support gathered from every other
   view, ghosts rejected, a merged blob allowed to stand for two markers; candidates on a
   static reflection (:mod:`.clutter`, learnt per view) ranked one view fewer;
3. :mod:`.labeller` — the points named as the 8 markers by an optimal assignment against the
   predicted markers, checked against what is rigid for this subject (:mod:`.rigid`), markers
   left out recovered from the free points;
4. :mod:`.identify` — acquisition and recovery from the 3D points alone (the standard pose in
   any stance, or any pose after a blackout), enumerating the labellings the subject's rigid
   lengths allow and choosing by geometry, anatomy, facing and recent motion.
"""

from .labeller import Labeller, LabelConfig, LabelQuality, bit_markers, marker_bits

__all__ = ["Labeller", "LabelConfig", "LabelQuality", "bit_markers", "marker_bits"]
