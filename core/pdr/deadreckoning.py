"""Dead reckoning: position after each step (Tian et al. 2014, eq. 1)."""

from __future__ import annotations

import math


class DeadReckoner:
    """Accumulates steps into an East/North position (m), eq. 1.

    ``x_k = x_0 + sum d_i cos(theta_i)``, ``y_k = y_0 + sum d_i sin(theta_i)``
    with ``x`` East, ``y`` North and ``theta`` the heading counter-clockwise
    from East (see :mod:`core`).

    Parameters
    ----------
    east_m, north_m : float
        Start position (m).
    """

    def __init__(self, *, east_m: float = 0.0, north_m: float = 0.0):
        self.start = (float(east_m), float(north_m))
        self.reset()

    def reset(self) -> None:
        self.east_m, self.north_m = self.start
        self.distance_m = 0.0
        self.n_steps = 0

    def update(self, length_m: float, heading_rad: float) -> tuple[float, float]:
        """Add one step; returns the new (east, north) position."""
        self.east_m += length_m * math.cos(heading_rad)  # eq. 1
        self.north_m += length_m * math.sin(heading_rad)
        self.distance_m += length_m
        self.n_steps += 1
        return self.east_m, self.north_m

    def run(self, lengths_m, headings_rad) -> list[tuple[float, float]]:
        """Positions after each step for whole arrays (same kernel as :meth:`update`)."""
        self.reset()
        return [self.update(float(d), float(h)) for d, h in zip(lengths_m, headings_rad)]
