"""Geometry on the hot path: signed-distance grids, decoding particles into grasps
(closing the fingers), collision checks (capsules, python-fcl) and their compiled kernels."""
