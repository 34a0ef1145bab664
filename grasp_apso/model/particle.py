"""The particle layout: which value of a swarm particle means what, as named slices.

A particle (D = 19 float64, SI) is the paper's Cg (eq. 7, 18 values, row-major 6x3) and
the wrist standoff offset::

    x[3*i + 0] = theta_i1   distal (coupled) flexion of finger i   -> LAYOUT.distal
    x[3*i + 1] = theta_i2   proximal flexion                        -> LAYOUT.proximal
    x[3*i + 2] = theta_i3   pivot (abduction)                       -> LAYOUT.pivot
    x[15:18]   = theta_x, theta_y, theta_z wrist angles             -> LAYOUT.wrist
    x[18]      = standoff offset, m                                 -> LAYOUT.standoff

with i = 0..4 for little, ring, middle, index, thumb. Use :data:`LAYOUT` instead of
literal indices.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ParticleLayout", "LAYOUT"]


class ParticleLayout:
    """Named slices of a particle (see the module docstring); constants only."""

    __slots__ = ()
    n_fingers = 5
    fingers = slice(0, 15)
    distal = slice(0, 15, 3)
    proximal = slice(1, 15, 3)
    pivot = slice(2, 15, 3)
    wrist = slice(15, 18)
    configuration = slice(0, 18)
    standoff = 18
    dims = 19

    def finger_values(self, x: np.ndarray) -> np.ndarray:
        """(..., D or 18 or 15) -> (..., 5, 3) view: per finger (distal, proximal, pivot)."""
        return x[..., self.fingers].reshape(x.shape[:-1] + (self.n_fingers, 3))

    def cg(self, x: np.ndarray) -> np.ndarray:
        """(D,) or (18,) -> (6, 3) copy: the paper's Cg rows little..thumb, wrist."""
        return np.asarray(x)[self.configuration].reshape(6, 3).copy()


#: The one layout of this package.
LAYOUT = ParticleLayout()
