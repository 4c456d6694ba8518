"""Geometry of the track view's GPS layer, plain Python (numpy, no Kivy), so it is tested without a window.

Everything takes screen coordinates (pixels, y up) or metres as documented and
returns flat lists in the layout Kivy's ``Mesh`` (``x, y, u, v`` per vertex)
and ``Line`` (``x0, y0, x1, y1, ...``) take, built with numpy in one go: the
view calls these once per redraw, not once per fix or step.

Uncertainty ellipse
    The view draws the **2-sigma** ellipse (:data:`ELLIPSE_SIGMA`) of the
    position covariance ``cov_en_m2 = (var_e, cov_en, var_n)``: the points
    ``p`` with ``p^T C^-1 p = k^2``, semi-axes ``k sqrt(eigenvalue)`` along the
    eigenvectors of the 2x2 ``C``.  For a 2-D Gaussian it holds
    ``1 - exp(-k^2 / 2)`` = 86 % of the positions (the 1-sigma one only 39 %).
"""

from __future__ import annotations

import math

import numpy as np

#: the drawn uncertainty ellipse is this many standard deviations (2: 86 % of a 2-D Gaussian)
ELLIPSE_SIGMA = 2.0


def covariance_ellipse(cov_en_m2, k_sigma: float = ELLIPSE_SIGMA) -> tuple[float, float, float]:
    """``(semi_major_m, semi_minor_m, angle_rad)`` of the ``k_sigma`` ellipse of ``(var_e, cov_en, var_n)``.

    ``angle_rad`` is the major axis' direction, counter-clockwise from East (in (-pi/2, pi/2]).
    Negative eigenvalues (rounding of a nearly singular matrix) count as 0.
    """
    ve, c, vn = (float(v) for v in cov_en_m2)
    w, vec = np.linalg.eigh(np.array([[ve, c], [c, vn]]))  # ascending eigenvalues
    w = np.clip(w, 0.0, None)
    major = vec[:, 1]
    angle = math.atan2(major[1], major[0])
    if angle <= -math.pi / 2:
        angle += math.pi
    elif angle > math.pi / 2:
        angle -= math.pi
    return k_sigma * math.sqrt(w[1]), k_sigma * math.sqrt(w[0]), angle


def ellipse_points(cx: float, cy: float, a: float, b: float, angle_rad: float, n: int = 48) -> list:
    """``n`` points ``[x0, y0, x1, y1, ...]`` on the ellipse of semi-axes ``a`` (along ``angle_rad``) and ``b``."""
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    u, v = a * np.cos(t), b * np.sin(t)
    xy = np.empty(2 * n)
    xy[0::2] = cx + c * u - s * v
    xy[1::2] = cy + s * u + c * v
    return xy.tolist()


def fan_mesh(cx: float, cy: float, outline: list) -> tuple[list, list]:
    """A filled polygon (``triangle_fan``) around ``(cx, cy)``: vertices and indices for a ``Mesh``."""
    xy = np.concatenate([[cx, cy], outline, outline[:2]]).reshape(-1, 2)
    verts = np.zeros((len(xy), 4))
    verts[:, :2] = xy
    return verts.ravel().tolist(), list(range(len(xy)))


def circles_mesh(x, y, r, n: int = 24) -> tuple[list, list]:
    """Circle outlines (centres ``x, y``, radii ``r``, pixels) as one ``Mesh`` in ``lines`` mode."""
    x, y, r = (np.asarray(v, dtype=float).reshape(-1) for v in (x, y, r))
    m = len(x)
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    verts = np.zeros((m, n, 4))
    verts[:, :, 0] = x[:, None] + r[:, None] * np.cos(t)
    verts[:, :, 1] = y[:, None] + r[:, None] * np.sin(t)
    k = np.arange(n)
    seg = np.stack([k, (k + 1) % n], axis=1)  # (n, 2) within one circle
    idx = (seg[None, :, :] + n * np.arange(m)[:, None, None]).ravel()
    return verts.ravel().tolist(), idx.tolist()


def squares_mesh(x, y, half: float) -> tuple[list, list]:
    """Small filled squares of side ``2 half`` (pixels) centred on ``x, y``: one ``Mesh`` in ``triangles`` mode."""
    x, y = (np.asarray(v, dtype=float).reshape(-1) for v in (x, y))
    m = len(x)
    verts = np.zeros((m, 4, 4))
    for k, (dx, dy) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        verts[:, k, 0] = x + dx * half
        verts[:, k, 1] = y + dy * half
    quad = np.array([0, 1, 2, 2, 3, 0])
    idx = (quad[None, :] + 4 * np.arange(m)[:, None]).ravel()
    return verts.ravel().tolist(), idx.tolist()


def runs(flags) -> list[tuple[int, int]]:
    """Point ranges ``(i0, i1)`` (inclusive) of the stretches of a track whose steps have ``flags`` true.

    Step ``k`` goes from track point ``k`` to point ``k + 1`` (point 0 is the start), so a run of steps
    ``i..j`` is drawn through points ``i..j + 1``.
    """
    f = np.asarray(flags, dtype=bool).reshape(-1)
    if not f.any():
        return []
    d = np.diff(np.concatenate([[False], f, [False]]).astype(np.int8))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)  # one past the last step of the run
    return [(int(a), int(b)) for a, b in zip(starts, ends)]


def gps_status_text(n_fixes: int, n_used: int, cov_en_m2, anchored: bool, k_sigma: float = ELLIPSE_SIGMA,
                    verdict: str = "") -> str:
    """The legend's first line: ``GPS: n fixes, m used · ±X m (2σ)``, X the ellipse's semi-major axis;
    with ``verdict``, why the last fix was not used (``· last fix: ...``)."""
    head = f"GPS: {n_fixes} fix{'es' if n_fixes != 1 else ''}, {n_used} used"
    tail = f" · last fix: {verdict}" if verdict and verdict != "used" else ""
    if not anchored or cov_en_m2 is None:
        return head + (" · waiting for a good fix" if n_fixes else " · no fix yet") + tail
    a, _, _ = covariance_ellipse(cov_en_m2, k_sigma)
    return f"{head} · ±{a:.1f} m ({k_sigma:g}σ)" + tail


# -- the view's lines, bounded (issue #30) ------------------------------------------------------------------

#: a line the session keeps for the view is thinned when it passes this many points ...
VIEW_MAX_POINTS = 10000
#: ... keeping its last this many at full resolution (the old part decimated to at most half the maximum)
VIEW_RECENT_POINTS = 2000
#: fixes the session keeps for the view: the last this many (the view draws 10 000: ``MAX_FIX_CHUNKS`` of ``FIX_CHUNK``)
VIEW_MAX_FIXES = 10000


def decimate_indices(xs, ys, tol: float) -> list[int]:
    """The indices of the points of a polyline that :func:`decimate` keeps."""
    n = len(xs)
    if tol <= 0 or n <= 2:
        return list(range(n))
    t2 = tol * tol
    out = [0]
    lx, ly = xs[0], ys[0]
    for i in range(1, n - 1):
        x, y = xs[i], ys[i]
        if (x - lx) * (x - lx) + (y - ly) * (y - ly) >= t2:
            out.append(i)
            lx, ly = x, y
    out.append(n - 1)
    return out


def decimate(xs: list, ys: list, tol: float) -> tuple[list, list]:
    """The points of a polyline with those closer than ``tol`` to the last kept one dropped; the first and
    the last are always kept (chunks stay joined).  ``tol <= 0``: all of them."""
    if tol <= 0 or len(xs) <= 2:
        return xs, ys
    idx = decimate_indices(xs, ys, tol)
    return [xs[i] for i in idx], [ys[i] for i in idx]


def thin_line(east: list, north: list, tags: list | None = None, *, max_points: int = VIEW_MAX_POINTS,
              recent: int = VIEW_RECENT_POINTS, tol_m: float = 1.0) -> tuple[list, list, list | None, float]:
    """A view line that grew past ``max_points``, thinned: new lists ``(east, north, tags, tol)``.

    The last ``recent`` points stay; the ones before are :func:`decimate` d with the smallest tolerance of
    ``tol_m, 2 tol_m, 4 tol_m, ...`` that leaves at most ``max_points // 2`` points in all (a day's 100 km
    in 10 000 points: a point every 20 m or so of the old part, far below a pixel of the whole walk on a
    phone screen; a zoom into it draws it that coarse).  ``tags`` (one per segment: point ``k + 1``'s, as
    the fused track's source) keep the tag of the last segment each new one covers.  Thinning again costs
    one pass, so a line costs O(1) per point on average and at most ``max_points`` in memory.
    """
    head = max(len(east) - recent, 1)
    tol = tol_m
    while True:
        idx = decimate_indices(east[:head], north[:head], tol)
        if len(idx) + len(east) - head <= max_points // 2 or tol > 1e7:
            break
        tol *= 2.0
    idx += range(head, len(east))
    new_tags = [tags[i - 1] for i in idx[1:]] if tags is not None else None
    return [east[i] for i in idx], [north[i] for i in idx], new_tags, tol
