"""Camera calibration: intrinsics, wand extrinsics with bundle adjustment, floor, self-calibration.

CLI: ``samba-calibrate`` (:mod:`samba_server.cli.calibrate`). Heavy imports (cv2, scipy) live
in the submodules.
"""
