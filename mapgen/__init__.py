"""Geometry of the real I-24 segment: alignment, elevation, lanes, road transforms and meshes."""
