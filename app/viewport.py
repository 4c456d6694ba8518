"""Map between the track in metres (East, North) and widget pixels: pan, zoom, fit, scale bar.

Plain Python (numpy for whole tracks) so it is tested without a window.
Screen y grows upwards (Kivy), so North is up and an ENU heading angle is
also the on-screen angle.
"""

from __future__ import annotations

import math

import numpy as np

MIN_SCALE = 0.05  # px per metre (about 20 km across a phone screen)
MAX_SCALE = 400.0  # px per metre


def nice_length(max_m: float) -> float:
    """Largest 1, 2 or 5 x 10^k metres not above ``max_m`` (for the scale bar)."""
    if not max_m > 0 or not math.isfinite(max_m):
        return 0.0
    k = math.floor(math.log10(max_m))
    for m in (5, 2, 1):
        v = m * 10.0 ** k
        if v <= max_m * (1 + 1e-12):
            return v
    return 10.0 ** k


def format_length(m: float) -> str:
    if m >= 1000:
        return f"{m / 1000:g} km"
    if m >= 1:
        return f"{m:g} m"
    return f"{m * 100:g} cm"


class Viewport:
    """Widget rectangle ``(x0, y0, width, height)`` showing metres at ``scale`` px/m around ``center``."""

    def __init__(self, width: float = 400, height: float = 400, *, x0: float = 0, y0: float = 0,
                 scale: float = 20.0, center=(0.0, 0.0)):
        self.x0, self.y0, self.width, self.height = float(x0), float(y0), float(width), float(height)
        self.scale = float(scale)
        self.center = (float(center[0]), float(center[1]))

    def set_rect(self, x0, y0, width, height) -> None:
        self.x0, self.y0, self.width, self.height = float(x0), float(y0), float(width), float(height)

    def to_screen(self, east: float, north: float) -> tuple[float, float]:
        return (self.x0 + self.width / 2 + (east - self.center[0]) * self.scale,
                self.y0 + self.height / 2 + (north - self.center[1]) * self.scale)

    def to_world(self, x: float, y: float) -> tuple[float, float]:
        return (self.center[0] + (x - self.x0 - self.width / 2) / self.scale,
                self.center[1] + (y - self.y0 - self.height / 2) / self.scale)

    def to_screen_arrays(self, east, north) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`to_screen` of whole arrays: ``(x, y)`` pixel arrays."""
        e = np.asarray(east, dtype=float)
        n = np.asarray(north, dtype=float)
        return (self.x0 + self.width / 2 + (e - self.center[0]) * self.scale,
                self.y0 + self.height / 2 + (n - self.center[1]) * self.scale)

    def points(self, east, north) -> list:
        """Interleaved screen coordinates ``[x0, y0, x1, y1, ...]`` for a Kivy ``Line``."""
        x, y = self.to_screen_arrays(east, north)
        xy = np.empty(2 * len(x))
        xy[0::2] = x
        xy[1::2] = y
        return xy.tolist()

    def pan(self, dx_px: float, dy_px: float) -> None:
        """Move the content by ``(dx, dy)`` pixels (a finger drag)."""
        self.center = (self.center[0] - dx_px / self.scale, self.center[1] - dy_px / self.scale)

    def zoom_at(self, factor: float, x: float, y: float) -> None:
        """Zoom by ``factor`` keeping the world point under screen ``(x, y)`` in place."""
        we, wn = self.to_world(x, y)
        self.scale = min(max(self.scale * factor, MIN_SCALE), MAX_SCALE)
        self.center = (we - (x - self.x0 - self.width / 2) / self.scale,
                       wn - (y - self.y0 - self.height / 2) / self.scale)

    def follow(self, east: float, north: float) -> None:
        self.center = (float(east), float(north))

    def fit(self, east, north, margin_px: float = 40.0, min_extent_m: float = 10.0) -> None:
        """Show all of ``east``/``north`` with ``margin_px`` around (at least ``min_extent_m`` across)."""
        e = np.asarray(east, dtype=float)
        n = np.asarray(north, dtype=float)
        if len(e) == 0:
            return
        e0, e1, n0, n1 = float(e.min()), float(e.max()), float(n.min()), float(n.max())
        de = max(e1 - e0, min_extent_m)
        dn = max(n1 - n0, min_extent_m)
        w = max(self.width - 2 * margin_px, 10.0)
        h = max(self.height - 2 * margin_px, 10.0)
        self.scale = min(max(min(w / de, h / dn), MIN_SCALE), MAX_SCALE)
        self.center = ((e0 + e1) / 2, (n0 + n1) / 2)

    def scale_bar(self, max_px: float = 120.0) -> tuple[float, float]:
        """``(length_m, length_px)`` of a round scale bar at most ``max_px`` long."""
        m = nice_length(max_px / self.scale)
        return m, m * self.scale
