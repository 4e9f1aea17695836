"""Samba common code: skeleton definition, file formats, geometry shared by motes and server.

Keep this module light: heavy imports (cv2, scipy, zenoh) belong to the modules that use them.
"""

__version__ = "0.1.0"
