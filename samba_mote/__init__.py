"""Samba camera mote: frame sources, blob detection, marker tracking, transports, simulator.

Imports numpy, OpenCV, zenoh and pyserial only (no scipy): motes are small ARM boards.
"""
