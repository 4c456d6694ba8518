"""Plane geometry of floor plans, vectorised with numpy: segment crossings, a wall grid, point in polygon.

Segment intersection
    The orientation test of Cormen, Leiserson, Rivest & Stein, *Introduction
    to Algorithms*, 3rd ed., section 33.1 (``SEGMENTS-INTERSECT``):
    ``d = cross(b - a, c - a)`` tells on which side of the line ``ab`` the
    point ``c`` lies.  Segments ``p0p1`` and ``q0q1`` intersect iff ``q0`` and
    ``q1`` are on different sides of (or on) ``p0p1`` and ``p0``, ``p1`` on
    different sides of (or on) ``q0q1``; when all four points are collinear
    the segments intersect iff their projections overlap.  Touching counts
    as intersecting (a particle that ends on a wall has hit it).

Wall grid
    A uniform grid of square cells of ``cell_m``; each cell lists the walls
    whose bounding box overlaps the cell's 3 x 3 neighbourhood.  A move
    shorter than ``cell_m`` that starts in a cell stays inside that
    neighbourhood, so it need only be tested against that one list: the cost
    of a query is bounded by the densest neighbourhood, not the plan's size.
    Longer moves (rare: ``cell_m`` is chosen above the longest step) are
    tested against every wall.

Point in polygon
    The even-odd (crossing number) rule: a horizontal ray from the point
    crosses the polygon's boundary an odd number of times iff the point is
    inside (Shimrat 1962, "Algorithm 112: position of point relative to
    polygon", CACM 5(8):434).
"""

from __future__ import annotations

import numpy as np


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _on_segment_box(px, py, ax, ay, bx, by):
    """Whether collinear point p lies within the bounding box of segment ab."""
    return ((np.minimum(ax, bx) <= px) & (px <= np.maximum(ax, bx))
            & (np.minimum(ay, by) <= py) & (py <= np.maximum(ay, by)))


def segments_intersect(p0, p1, q0, q1) -> np.ndarray:
    """Element-wise: does segment ``p0p1`` touch or cross segment ``q0q1``?  Arrays ``(..., 2)``, broadcast.

    CLRS section 33.1 (see the module docstring).  Returns a boolean array of
    the broadcast shape without the last axis.
    """
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    ax, ay, bx, by = p0[..., 0], p0[..., 1], p1[..., 0], p1[..., 1]
    cx, cy, dx, dy = q0[..., 0], q0[..., 1], q1[..., 0], q1[..., 1]
    return _intersect(ax, ay, bx, by, cx, cy, dx, dy)


def _intersect(ax, ay, bx, by, cx, cy, dx, dy):
    d1 = _cross(dx - cx, dy - cy, ax - cx, ay - cy)  # side of a relative to cd
    d2 = _cross(dx - cx, dy - cy, bx - cx, by - cy)  # side of b relative to cd
    d3 = _cross(bx - ax, by - ay, cx - ax, cy - ay)  # side of c relative to ab
    d4 = _cross(bx - ax, by - ay, dx - ax, dy - ay)  # side of d relative to ab
    zero = (d1 == 0) | (d2 == 0) | (d3 == 0) | (d4 == 0)
    proper = (np.signbit(d1) != np.signbit(d2)) & (np.signbit(d3) != np.signbit(d4)) & ~zero
    if not np.any(zero):  # the usual case in floating point: no point on another segment's line
        return proper
    ax, ay, bx, by, cx, cy, dx, dy, d1, d2, d3, d4 = np.broadcast_arrays(ax, ay, bx, by, cx, cy, dx, dy,
                                                                        d1, d2, d3, d4)
    z = zero
    touch = ((d1[z] == 0) & _on_segment_box(ax[z], ay[z], cx[z], cy[z], dx[z], dy[z])) \
        | ((d2[z] == 0) & _on_segment_box(bx[z], by[z], cx[z], cy[z], dx[z], dy[z])) \
        | ((d3[z] == 0) & _on_segment_box(cx[z], cy[z], ax[z], ay[z], bx[z], by[z])) \
        | ((d4[z] == 0) & _on_segment_box(dx[z], dy[z], ax[z], ay[z], bx[z], by[z]))
    out = np.array(proper, dtype=bool, copy=True)
    out[z] |= touch
    return out


class WallGrid:
    """Walls ``(M, 4)`` as ``x0, y0, x1, y1`` (m) in a uniform grid, for crossing queries of many short moves.

    ``cell_m`` should exceed the longest move tested (a step plus its noise);
    longer moves are still answered exactly, against all walls.
    """

    def __init__(self, walls, cell_m: float = 2.0):
        w = np.asarray(walls, dtype=float).reshape(-1, 4)
        if not np.all(np.isfinite(w)):
            raise ValueError("walls must be finite")
        if not cell_m > 0:
            raise ValueError("cell_m must be positive")
        self.walls = w
        self.cell_m = float(cell_m)
        m = len(w)
        if m:
            lo = np.minimum(w[:, :2], w[:, 2:]).min(axis=0)
            hi = np.maximum(w[:, :2], w[:, 2:]).max(axis=0)
        else:
            lo = hi = np.zeros(2)
        self.origin = lo - cell_m  # one empty ring of cells around the walls
        self.shape = tuple(int(v) for v in np.floor((hi - self.origin) / cell_m).astype(int) + 2)
        nx, ny = self.shape
        # cells overlapped by each wall's bounding box, widened by one cell (the 3 x 3 neighbourhood)
        c_lo = np.floor((np.minimum(w[:, :2], w[:, 2:]) - self.origin) / cell_m).astype(int) - 1
        c_hi = np.floor((np.maximum(w[:, :2], w[:, 2:]) - self.origin) / cell_m).astype(int) + 1
        c_lo = np.clip(c_lo, 0, [nx - 1, ny - 1])
        c_hi = np.clip(c_hi, 0, [nx - 1, ny - 1])
        spans = (c_hi[:, 0] - c_lo[:, 0] + 1) * (c_hi[:, 1] - c_lo[:, 1] + 1)
        wall_idx = np.repeat(np.arange(m), spans)
        k = np.arange(int(spans.sum())) - np.repeat(np.cumsum(spans) - spans, spans)
        width = np.repeat(c_hi[:, 0] - c_lo[:, 0] + 1, spans)
        cx = np.repeat(c_lo[:, 0], spans) + k % np.maximum(width, 1)
        cy = np.repeat(c_lo[:, 1], spans) + k // np.maximum(width, 1)
        cell = cx * ny + cy
        order = np.argsort(cell, kind="stable")
        self._cell_walls = wall_idx[order]
        counts = np.bincount(cell, minlength=nx * ny)
        self._start = np.concatenate([[0], np.cumsum(counts)])
        self.max_per_cell = int(counts.max()) if len(counts) else 0

    def cell_of(self, xy) -> np.ndarray:
        """Flat cell index of points ``(N, 2)`` (-1 outside the grid)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        c = np.floor((xy - self.origin) / self.cell_m)
        nx, ny = self.shape
        inside = np.all(np.isfinite(c), axis=1) & (c[:, 0] >= 0) & (c[:, 0] < nx) & (c[:, 1] >= 0) & (c[:, 1] < ny)
        out = np.full(len(xy), -1, dtype=np.int64)
        out[inside] = (c[inside, 0] * ny + c[inside, 1]).astype(np.int64)
        return out

    def crosses(self, start, end) -> np.ndarray:
        """Boolean ``(N,)``: does the move ``start[i] -> end[i]`` touch or cross any wall?"""
        a = np.asarray(start, dtype=float).reshape(-1, 2)
        b = np.asarray(end, dtype=float).reshape(-1, 2)
        n = len(a)
        hit = np.zeros(n, dtype=bool)
        if n == 0 or len(self.walls) == 0:
            return hit
        cell = self.cell_of(a)
        long_move = np.hypot(*(b - a).T) >= self.cell_m
        slow = long_move | (cell < 0)
        fast = np.flatnonzero(~slow)
        if len(fast):
            c = cell[fast]
            counts = self._start[c + 1] - self._start[c]
            move = np.repeat(fast, counts)
            first = np.repeat(self._start[c], counts)
            k = np.arange(len(move)) - np.repeat(np.cumsum(counts) - counts, counts)
            w = self.walls[self._cell_walls[first + k]]
            x = _intersect(a[move, 0], a[move, 1], b[move, 0], b[move, 1], w[:, 0], w[:, 1], w[:, 2], w[:, 3])
            hit[move[x]] = True
        for i in np.flatnonzero(slow):  # rare: outside the grid's cells or longer than a cell
            w = self.walls
            hit[i] = bool(np.any(_intersect(a[i, 0], a[i, 1], b[i, 0], b[i, 1], w[:, 0], w[:, 1], w[:, 2], w[:, 3])))
        return hit


def points_in_polygon(xy, ring) -> np.ndarray:
    """Boolean ``(N,)``: is each point inside the closed ring ``(K, 2)`` (even-odd rule; see module docstring)?"""
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    r = np.asarray(ring, dtype=float).reshape(-1, 2)
    if len(r) < 3:
        return np.zeros(len(p), dtype=bool)
    x0, y0 = r[:, 0], r[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    px, py = p[:, 0:1], p[:, 1:2]
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    return np.sum(straddle & (px < x_cross), axis=1) % 2 == 1


def ring_segments(ring) -> np.ndarray:
    """The edges ``(K, 4)`` of a closed ring ``(K, 2)`` (the closing edge included, repeated end point dropped)."""
    r = np.asarray(ring, dtype=float).reshape(-1, 2)
    if len(r) > 1 and np.all(r[0] == r[-1]):
        r = r[:-1]
    if len(r) < 2:
        return np.zeros((0, 4))
    return np.column_stack([r, np.roll(r, -1, axis=0)])


def polygon_area(ring) -> float:
    """Signed area (m^2) of a ring, positive counter-clockwise (the shoelace formula)."""
    r = np.asarray(ring, dtype=float).reshape(-1, 2)
    if len(r) < 3:
        return 0.0
    return 0.5 * float(np.sum(r[:, 0] * np.roll(r[:, 1], -1) - np.roll(r[:, 0], -1) * r[:, 1]))
