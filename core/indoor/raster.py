"""Walls from a floor-plan image: threshold, then vectorise the wall mask's boundary (numpy only).

Where a floor exists only as an image (the IPIN ``Map_Floor_*.png``, the
Microsoft ``floor_image.png``), :func:`walls_from_image` turns it into wall
segments in metres, always by the same documented steps, never by a guess
per file:

1. **Threshold.**  A pixel is wall when its grey level is below
   ``threshold`` (dark lines on a light background).  The default threshold
   is Otsu's (N. Otsu 1979, "A threshold selection method from gray-level
   histograms", IEEE Trans. SMC 9(1):62-66): the grey level that maximises
   the between-class variance ``w0 w1 (mu0 - mu1)^2`` of the histogram.
   Transparent pixels count as background (:func:`desktop.floor_images.read_floor_image`).
2. **Cells.**  The mask is cut into square blocks of ``cell_px`` pixels
   (default: the block nearest to ``cell_m``, 0.1 m); a block is wall when
   any of its pixels is (so a one-pixel line survives).
3. **Vectorise.**  Every edge between a wall block and a free block (or the
   image border) is a wall segment; collinear neighbouring edges are merged
   into one segment by run-length coding of each grid line.  The result is
   watertight: a path from a free block into a wall block crosses a segment,
   so no particle passes through a drawn wall, and doors (gaps wider than a
   block) stay open.  Diagonal walls become staircases of block edges.

The result is plan metres, ``x`` to the right and ``y`` up from
``origin_px`` (column, row), ``m_per_px`` metres a pixel.

Reading the image file
    is not done here (``core`` is numpy only): :func:`desktop.floor_images.read_floor_image`
    reads it with Pillow on the desktop.  On the phone the app decodes
    images with Kivy and passes the grey array, or -- better -- the walls are
    extracted once on the desktop and shipped in our GeoJSON
    (:func:`core.indoor.floorplan.write_geojson`), which the phone reads
    with :mod:`json` alone.
"""

from __future__ import annotations

import numpy as np

#: default size of a block of the wall mask (m)
DEFAULT_CELL_M = 0.1


def otsu_threshold(gray) -> float:
    """Otsu's threshold of grey levels 0-255 (see the module docstring); the wall class is ``gray < threshold``."""
    g = np.clip(np.asarray(gray, dtype=float).ravel(), 0, 255)
    hist = np.bincount(g.astype(np.int64), minlength=256).astype(float)
    total = hist.sum()
    if total == 0:
        return 128.0
    p = hist / total
    w0 = np.cumsum(p)  # class 0: levels 0..k
    mu = np.cumsum(p * np.arange(256))
    mu_t = mu[-1]
    w1 = 1.0 - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mu_t * w0 - mu) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = -1.0
    k = int(np.argmax(between))
    return float(k) + 1.0  # levels 0..k are the dark class


def _block_any(mask: np.ndarray, b: int) -> np.ndarray:
    h, w = mask.shape
    hb, wb = -(-h // b), -(-w // b)
    pad = np.zeros((hb * b, wb * b), dtype=bool)
    pad[:h, :w] = mask
    return pad.reshape(hb, b, wb, b).any(axis=(1, 3))


def _runs(diff: np.ndarray):
    """Runs of True along axis 1 of a 2-D boolean array: (row, first column, column after the last)."""
    rows, cols = diff.shape
    padded = np.zeros((rows, cols + 2), dtype=np.int8)
    padded[:, 1:-1] = diff
    d = np.diff(padded, axis=1)
    r0, c0 = np.nonzero(d == 1)
    r1, c1 = np.nonzero(d == -1)  # row-major order: the k-th start and the k-th end belong together
    return r0, c0, c1


def mask_boundary_segments(mask) -> np.ndarray:
    """Segments ``(M, 4)`` in block units (x = column, y = row, both down/right) along the wall mask's boundary."""
    m = np.asarray(mask, dtype=bool)
    h, w = m.shape
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = m
    # horizontal edges: the line y = r (r = 0..h) between rows r-1 and r
    hdiff = pad[:-1, 1:-1] != pad[1:, 1:-1]
    r, c0, c1 = _runs(hdiff)
    horiz = np.column_stack([c0, r, c1, r]).astype(float)
    # vertical edges: the line x = c (c = 0..w) between columns c-1 and c
    vdiff = (pad[1:-1, :-1] != pad[1:-1, 1:]).T
    c, r0, r1 = _runs(vdiff)
    vert = np.column_stack([c, r0, c, r1]).astype(float)
    return np.vstack([horiz, vert])


def walls_from_image(gray, m_per_px: float, *, threshold: float | None = None, cell_px: int | None = None,
                     cell_m: float = DEFAULT_CELL_M, origin_px=(0.0, 0.0)) -> np.ndarray:
    """Wall segments ``(M, 4)`` in plan metres from a grey image (see the module docstring)."""
    g = np.asarray(gray, dtype=float)
    if g.ndim != 2 or not g.size:
        raise ValueError("walls_from_image needs a non-empty 2-D grey image")
    if not m_per_px > 0:
        raise ValueError("m_per_px must be positive")
    thr = otsu_threshold(g) if threshold is None else float(threshold)
    b = int(cell_px) if cell_px else max(1, int(round(cell_m / m_per_px)))
    blocks = _block_any(g < thr, b)
    seg = mask_boundary_segments(blocks) * (b * m_per_px)  # metres, x right, y down from the top-left corner
    ox, oy = (float(v) * m_per_px for v in origin_px)
    out = np.empty_like(seg)
    out[:, 0::2] = seg[:, 0::2] - ox
    out[:, 1::2] = oy - seg[:, 1::2]
    return out
