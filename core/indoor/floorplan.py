"""The floor-plan model and its readers/writers: walkable area and walls in plan metres, with a georeference.

The model
=========
:class:`FloorPlan` holds, in the plan's own metre frame (x East, y North
unless the georeference rotates it):

``areas``
    Walkable polygons: ``(outer_ring, [hole_ring, ...])``, rings ``(K, 2)``.
``obstacles``
    Rings that are not walkable (shops, pillars) wherever they are.
``wall_lines``
    Explicit walls, ``(M, 4)`` segments ``x0, y0, x1, y1``.

The particle filter (:mod:`core.indoor.particles`) sees :attr:`FloorPlan.walls`:
the wall lines, every obstacle and hole edge, and the walkable rings' edges
except an edge two walkable polygons share (drawn twice, once each way: it is
an opening between them, not a wall).  A point is walkable
(:meth:`FloorPlan.is_walkable`) when it is inside a walkable polygon, outside
its holes and outside every obstacle; a plan without walkable polygons (walls
only, e.g. from an image) counts every point as walkable.

Georeference (:class:`Georeference`)
    ``origin`` (lat, lon, degrees WGS-84), ``rotation_rad`` and per-axis
    ``scale``: a plan point ``p`` is at local ENU ``R(rotation) (scale * p)``
    about ``origin`` (``R`` counter-clockwise), and that ENU point is turned
    into latitude/longitude by :mod:`core.geodesy` (the project's one geodesy).

Formats
=======
Our own GeoJSON (:func:`read_geojson`, :func:`write_geojson`)
    A GeoJSON FeatureCollection (RFC 7946) that any GIS tool can draw.  Every
    feature has a ``"kind"`` property: ``"walkable"`` (Polygon/MultiPolygon,
    holes allowed), ``"obstacle"`` (Polygon/MultiPolygon; only the outer ring
    counts, so an obstacle around a courtyard is drawn as several) or ``"wall"``
    (LineString/MultiLineString).  Without ``kind``, polygons are walkable
    and lines are walls.  Coordinates are WGS-84 ``[lon, lat]`` as RFC 7946
    says, unless the optional top-level member ``"pdr_floorplan"`` says
    ``"units": "m"`` (plan metres)::

        "pdr_floorplan": {"version": 1, "units": "m" | "deg", "name": "...", "floor": "F3",
                          "origin_lat_lon": [lat, lon], "rotation_deg": 0.0, "scale": [1.0, 1.0]}

    In degrees the plan frame is local ENU about ``origin_lat_lon`` (default:
    the centre of the coordinates' bounding box) and the file's rotation and
    scale are ignored; in metres they are the plan's georeference.
Microsoft indoor location 2020 (:func:`read_ms_floor`)
    ``geojson_map.json(.gz)`` (the floor outline first, then one polygon per
    shop, WGS-84) and ``floor_info.json`` (the map's width and height in m).
    The surveyor's waypoints are metres East/North of the south-west corner
    of the GeoJSON's bounding box, scaled so that the box measures exactly
    ``width x height`` (the competition's own frame: a spherical plate carree,
    0.1 % off the ellipsoid East and 0.4 % North on site2/F3).  The reader
    therefore maps the polygons through :mod:`core.geodesy` about that
    corner and then scales each axis to ``floor_info``'s size; the
    georeference keeps those scales.  The outline is walkable, the shops are
    obstacles (the surveyors walk the mall's corridors: see docs/indoor.md
    for the check on the traces).  ``floor_image.png`` is the same map drawn
    at ``width / pixels`` metres a pixel (readable with :func:`desktop.floor_images.read_floor_image`).
IPIN floor images (:func:`read_ipin_cal`, :func:`read_ipin_floor`)
    A ``.cal`` file of the GetSensorData tools: per floor the image file, the
    floor number, the building, latitude and longitude of the image centre,
    the image's rotation (deg) and its scale (m/pixel).  Walls come from the
    image by :func:`core.indoor.raster.walls_from_image`.
"""

from __future__ import annotations

import gzip
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from core.geodesy import enu_to_geodetic, geodetic_to_enu
from core.indoor.geometry import WallGrid, points_in_polygon, ring_segments, segments_intersect
from core.metrics import rotate

FORMAT_VERSION = 1
KINDS = ("walkable", "obstacle", "wall")


@dataclass(frozen=True)
class Georeference:
    """Where a plan is on the Earth: plan point ``p`` -> local ENU ``R(rotation) (scale * p)`` about ``origin``."""

    origin_lat_deg: float
    origin_lon_deg: float
    rotation_rad: float = 0.0
    scale_east: float = 1.0
    scale_north: float = 1.0

    @property
    def origin(self) -> tuple[float, float]:
        return (self.origin_lat_deg, self.origin_lon_deg)

    def plan_to_enu(self, xy) -> np.ndarray:
        p = np.asarray(xy, dtype=float).reshape(-1, 2) * [self.scale_east, self.scale_north]
        return rotate(p, self.rotation_rad)

    def enu_to_plan(self, en) -> np.ndarray:
        return rotate(np.asarray(en, dtype=float).reshape(-1, 2), -self.rotation_rad) / [self.scale_east,
                                                                                        self.scale_north]

    def to_geodetic(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """Plan points ``(N, 2)`` -> (lat_deg, lon_deg) arrays."""
        en = self.plan_to_enu(xy)
        lat, lon = enu_to_geodetic(en[:, 0], en[:, 1], self.origin)
        return np.atleast_1d(lat), np.atleast_1d(lon)

    def from_geodetic(self, lat_deg, lon_deg) -> np.ndarray:
        """(lat_deg, lon_deg) -> plan points ``(N, 2)``."""
        e, n = geodetic_to_enu(np.atleast_1d(np.asarray(lat_deg, dtype=float)),
                               np.atleast_1d(np.asarray(lon_deg, dtype=float)), self.origin)
        return self.enu_to_plan(np.column_stack([e, n]))


def _ring(r) -> np.ndarray:
    a = np.asarray(r, dtype=float).reshape(-1, 2)
    if len(a) > 1 and np.all(a[0] == a[-1]):
        a = a[:-1]
    if len(a) < 3 or not np.all(np.isfinite(a)):
        raise ValueError("a polygon ring needs 3 or more finite vertices")
    return a


class RingIndex:
    """A closed ring ``(K, 2)`` for point-in-polygon queries (the even-odd rule of
    :func:`~core.indoor.geometry.points_in_polygon`) in time proportional to the edges near the points.

    Points outside the ring's bounding box are outside; the others are tested against the edges of their
    horizontal band only (the band of height ``(y_max - y_min) / (K / per_band)`` the point's y falls in;
    each edge is listed in every band its y range overlaps): a horizontal ray from a point can only cross
    edges that straddle the point's y, and those all overlap its band.
    """

    def __init__(self, ring, per_band: int = 16):
        r = np.asarray(ring, dtype=float).reshape(-1, 2)
        self.ring = r
        self.lo = r.min(axis=0)
        self.hi = r.max(axis=0)
        k = len(r)
        self.bands = nb = max(1, k // per_band)
        y0, y1 = r[:, 1], np.roll(r[:, 1], -1)
        self.h = float(self.hi[1] - self.lo[1]) / nb or 1.0
        b0 = np.clip(np.floor((np.minimum(y0, y1) - self.lo[1]) / self.h).astype(np.int64), 0, nb - 1)
        b1 = np.clip(np.floor((np.maximum(y0, y1) - self.lo[1]) / self.h).astype(np.int64), 0, nb - 1)
        spans = b1 - b0 + 1
        edge = np.repeat(np.arange(k), spans)
        band = np.repeat(b0, spans) + np.arange(int(spans.sum())) - np.repeat(np.cumsum(spans) - spans, spans)
        order = np.argsort(band, kind="stable")
        self._edges = edge[order]
        self._start = np.concatenate([[0], np.cumsum(np.bincount(band, minlength=nb))])

    def contains(self, xy) -> np.ndarray:
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(p), dtype=bool)
        box = np.flatnonzero(np.all((p >= self.lo) & (p <= self.hi), axis=1))
        if not len(box) or len(self.ring) < 3:
            return out
        if self.bands == 1:
            out[box] = points_in_polygon(p[box], self.ring)
            return out
        q = p[box]
        band = np.clip(np.floor((q[:, 1] - self.lo[1]) / self.h).astype(np.int64), 0, self.bands - 1)
        counts = self._start[band + 1] - self._start[band]
        pt = np.repeat(np.arange(len(q)), counts)
        first = np.repeat(self._start[band], counts)
        e = self._edges[first + np.arange(len(pt)) - np.repeat(np.cumsum(counts) - counts, counts)]
        r = self.ring
        x0, y0 = r[e, 0], r[e, 1]
        nxt = (e + 1) % len(r)
        x1, y1 = r[nxt, 0], r[nxt, 1]
        px, py = q[pt, 0], q[pt, 1]
        straddle = (y0 > py) != (y1 > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
        n = np.bincount(pt[straddle & (px < x_cross)], minlength=len(q))
        out[box] = n % 2 == 1
        return out


@dataclass
class FloorPlan:
    """Walkable area and walls of one floor, in plan metres (see the module docstring)."""

    areas: list = field(default_factory=list)  #: [(outer ring (K, 2), [hole rings])]
    obstacles: list = field(default_factory=list)  #: [ring (K, 2)]
    wall_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    georef: Georeference | None = None
    name: str = ""
    floor: str = ""

    def __post_init__(self):
        self.areas = [(_ring(o), [_ring(h) for h in holes]) for o, holes in self.areas]
        self.obstacles = [_ring(r) for r in self.obstacles]
        self.wall_lines = np.asarray(self.wall_lines, dtype=float).reshape(-1, 4)
        if not np.all(np.isfinite(self.wall_lines)):
            raise ValueError("wall lines must be finite")
        self._walls = None
        self._grids = {}
        self._rings = {}

    @property
    def walls(self) -> np.ndarray:
        """Every barrier segment ``(M, 4)`` (see the module docstring), computed once."""
        if self._walls is None:
            outer = [ring_segments(o) for o, _ in self.areas]
            outer = np.vstack(outer) if outer else np.zeros((0, 4))
            if len(outer):  # an edge drawn by two walkable polygons (once each way) is an opening
                q = np.round(outer, 6)
                fwd = [tuple(r) for r in q]
                rev = {tuple(r) for r in q[:, [2, 3, 0, 1]]}
                outer = outer[[k not in rev for k in fwd]]
            rest = [ring_segments(h) for _, holes in self.areas for h in holes]
            rest += [ring_segments(r) for r in self.obstacles]
            self._walls = np.vstack([outer, self.wall_lines, *rest])
        return self._walls

    def grid(self, cell_m: float = 2.0) -> WallGrid:
        """The walls in a :class:`~core.indoor.geometry.WallGrid` of ``cell_m`` cells (cached)."""
        key = float(cell_m)
        if key not in self._grids:
            self._grids[key] = WallGrid(self.walls, cell_m=key)
        return self._grids[key]

    def _inside(self, p: np.ndarray, ring: np.ndarray) -> np.ndarray:
        """Points of ``p`` inside ``ring`` (even-odd rule) through the ring's :class:`RingIndex` (cached)."""
        key = id(ring)
        if key not in self._rings:
            self._rings[key] = RingIndex(ring)
        return self._rings[key].contains(p)

    def is_walkable(self, xy) -> np.ndarray:
        """Boolean ``(N,)``: inside a walkable polygon, outside its holes and every obstacle.

        Each ring answers through a :class:`RingIndex` (its bounding box, then the edges of one band), so a
        query costs the edges near the points, not the plan's size."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not self.areas:
            ok = np.ones(len(p), dtype=bool)
        else:
            ok = np.zeros(len(p), dtype=bool)
            for outer, holes in self.areas:
                inside = self._inside(p, outer)
                for h in holes:
                    inside &= ~self._inside(p, h)
                ok |= inside
        for r in self.obstacles:
            ok &= ~self._inside(p, r)
        return ok & np.all(np.isfinite(p), axis=1)

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of everything in the plan."""
        pts = [o for o, _ in self.areas] + self.obstacles + [self.wall_lines.reshape(-1, 2)]
        pts = np.vstack([p for p in pts if len(p)]) if any(len(p) for p in pts) else np.zeros((1, 2))
        return (float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max()))


# ---------------------------------------------------------------------------
# our GeoJSON format


def _open_text(path):
    path = str(path)
    if path.endswith(".gz"):
        return gzip.open(path, "rt", encoding="utf-8")
    return open(path, encoding="utf-8")


def _polygons(geom) -> list:
    t = geom.get("type")
    if t == "Polygon":
        return [geom["coordinates"]]
    if t == "MultiPolygon":
        return list(geom["coordinates"])
    return []


def _lines(geom) -> list:
    t = geom.get("type")
    if t == "LineString":
        return [geom["coordinates"]]
    if t == "MultiLineString":
        return list(geom["coordinates"])
    return []


def _coords(doc) -> np.ndarray:
    pts = []
    for f in doc.get("features", []):
        g = f.get("geometry") or {}
        for poly in _polygons(g):
            for r in poly:
                pts += [c[:2] for c in r]
        for line in _lines(g):
            pts += [c[:2] for c in line]
    return np.asarray(pts, dtype=float).reshape(-1, 2)


class PlanFileError(ValueError):
    """A floor-plan file that cannot be used; ``str()`` is one line naming the file and the feature."""


#: a plan file larger than this (its text, after gzip) is refused before it is parsed (the largest real plan
#: read here, a Microsoft mall floor, is about 1 MB of GeoJSON)
MAX_PLAN_BYTES = 64 << 20
#: a polygon ring or line with more vertices than this is refused (a corridor outline needs tens to hundreds;
#: simplify the ring, e.g. to 0.05 m, in a GIS tool)
MAX_RING_VERTICES = 100_000
#: every vertex of a plan together
MAX_PLAN_VERTICES = 500_000


def _where(source, index=None) -> str:
    at = f"{source}: " if source else ""
    return at + (f"feature {index}: " if index is not None else "")


def _coordinate_array(c, what: str, where: str, min_points: int, max_points: int) -> np.ndarray:
    """``c`` as an ``(K, 2)`` float array of finite [x, y] pairs, or a :class:`PlanFileError` (also for
    more than ``max_points``, counted before anything is converted)."""
    if not isinstance(c, list):
        raise PlanFileError(f"{where}{what} must be a list of [x, y] positions")
    if len(c) > max_points:
        raise PlanFileError(f"{where}{what} has {len(c)} vertices, over the limit of {max_points} "
                            "(core.indoor.floorplan.MAX_RING_VERTICES): simplify it (a corridor outline needs "
                            "hundreds)")
    a = None
    try:  # the usual case, [x, y] pairs: numpy converts the list at once
        a = np.asarray(c, dtype=float)
    except (TypeError, ValueError):
        pass
    if a is None or a.ndim != 2 or a.shape[1] < 2:
        if not all(isinstance(p, list) and len(p) >= 2 for p in c):
            raise PlanFileError(f"{where}{what} must be a list of [x, y] positions")
        try:
            a = np.asarray([p[:2] for p in c], dtype=float)
        except (TypeError, ValueError):
            raise PlanFileError(f"{where}{what} holds a position that is not two numbers") from None
    a = a[:, :2].reshape(-1, 2)
    if not np.all(np.isfinite(a)):
        raise PlanFileError(f"{where}{what} holds a position that is not finite")
    if len(a) < min_points:
        raise PlanFileError(f"{where}{what} needs {min_points} or more positions, found {len(a)}")
    return a


def _features(doc, source, max_ring_vertices: int, max_vertices: int) -> list:
    """The features of a plan document, checked: ``[(index, kind, polygons, lines)]`` with every ring and
    line an ``(K, 2)`` array in the file's units; a :class:`PlanFileError` naming the file and the feature."""
    feats = doc.get("features", [])
    if not isinstance(feats, list):
        raise PlanFileError(f"{_where(source)}'features' must be a list of features, found "
                            f"{type(feats).__name__}")
    out, total = [], 0
    for i, f in enumerate(feats):
        where = _where(source, i)
        if not isinstance(f, dict):
            raise PlanFileError(f"{where}a feature must be a JSON object, found {type(f).__name__}")
        g = f.get("geometry") or {}
        props = f.get("properties") or {}
        if not isinstance(g, dict) or not isinstance(props, dict):
            raise PlanFileError(f"{where}'geometry' and 'properties' must be JSON objects")
        t = g.get("type")
        coords = g.get("coordinates")
        if t in ("Polygon", "MultiPolygon", "LineString", "MultiLineString") and not isinstance(coords, list):
            raise PlanFileError(f"{where}a {t} needs a list of 'coordinates'")
        polys, lines = [], []
        if t == "Polygon" or t == "MultiPolygon":
            for k, poly in enumerate([coords] if t == "Polygon" else coords):
                if not isinstance(poly, list) or not poly:
                    raise PlanFileError(f"{where}polygon {k} must be a non-empty list of rings")
                polys.append([_coordinate_array(r, f"ring {j} of polygon {k}", where, 3, max_ring_vertices)
                              for j, r in enumerate(poly)])
        elif t == "LineString" or t == "MultiLineString":
            for k, line in enumerate([coords] if t == "LineString" else coords):
                lines.append(_coordinate_array(line, f"line {k}", where, 2, max_ring_vertices))
        total += sum(len(a) for a in [r for p in polys for r in p] + lines)
        if total > max_vertices:
            raise PlanFileError(f"{where}the plan has more than {max_vertices} vertices (the limit, "
                                "core.indoor.floorplan.MAX_PLAN_VERTICES): simplify it or split it into floors")
        kind = props.get("kind")
        if kind is None:
            kind = "walkable" if polys else "wall"
        if kind not in KINDS:
            raise PlanFileError(f"{where}unknown feature kind {str(kind)[:40]!r} (one of {', '.join(KINDS)})")
        out.append((i, kind, polys, lines))
    return out


def ring_self_crossing(ring) -> tuple[int, int] | None:
    """Two edges of a closed ring ``(K, 2)`` that cross or touch, other than neighbours at their shared vertex
    (the ring is not a simple polygon: the even-odd rule then makes part of it outside), or None.

    The edges are hashed into a uniform grid of cells two median edges wide (each edge in every cell its bounding
    box overlaps); only edges sharing a cell can meet, and those pairs are tested (CLRS 33.1,
    :func:`~core.indoor.geometry.segments_intersect`): about K tests for a plan's rings, not K^2."""
    seg = ring_segments(_ring(ring))
    k = len(seg)
    if k < 4:
        return None
    lo = np.minimum(seg[:, :2], seg[:, 2:])
    hi = np.maximum(seg[:, :2], seg[:, 2:])
    origin = lo.min(axis=0)
    ext = hi.max(axis=0) - origin
    cell = max(2.0 * float(np.median((hi - lo).max(axis=1))), float(ext.max()) / k, 1e-9)  # about 2 edges long
    c_lo = np.floor((lo - origin) / cell).astype(np.int64)
    c_hi = np.floor((hi - origin) / cell).astype(np.int64)
    ny = int(c_hi[:, 1].max()) + 1
    w = c_hi[:, 0] - c_lo[:, 0] + 1
    n_per = w * (c_hi[:, 1] - c_lo[:, 1] + 1)
    edge = np.repeat(np.arange(k), n_per)
    j = np.arange(int(n_per.sum())) - np.repeat(np.cumsum(n_per) - n_per, n_per)
    wr = np.repeat(w, n_per)
    key = (np.repeat(c_lo[:, 0], n_per) + j % wr) * ny + np.repeat(c_lo[:, 1], n_per) + j // wr
    order = np.argsort(key, kind="stable")
    key, edge = key[order], edge[order]
    start = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    count = np.diff(np.concatenate([start, [len(key)]]))
    g0 = np.repeat(start, count)  # each entry: its cell's first entry and size
    c = np.repeat(count, count)
    step = 1 << 16
    for a in range(0, len(key), step):  # the pairs of entries sharing a cell, a block of entries at a time
        pos = np.arange(a, min(a + step, len(key)))
        cc = c[pos]
        p = np.repeat(pos, cc)
        q = np.repeat(g0[pos], cc) + np.arange(int(cc.sum())) - np.repeat(np.cumsum(cc) - cc, cc)
        keep = q > p
        i, jj = edge[p[keep]], edge[q[keep]]
        gap = np.abs(i - jj)
        keep = (gap != 1) & (gap != k - 1) & (gap != 0)  # neighbours share a vertex
        i, jj = i[keep], jj[keep]
        if not len(i):
            continue
        hit = segments_intersect(seg[i, :2], seg[i, 2:], seg[jj, :2], seg[jj, 2:])
        if hit.any():
            m = int(np.flatnonzero(hit)[0])
            return tuple(sorted((int(i[m]), int(jj[m]))))
    return None


def _check_simple(ring_plan: np.ndarray, what: str, where: str) -> None:
    hit = ring_self_crossing(ring_plan)
    if hit is not None:
        e = ring_segments(_ring(ring_plan))[hit[0]]
        raise PlanFileError(f"{where}{what} crosses itself (edges {hit[0]} and {hit[1]}, near "
                            f"{e[0]:.2f}, {e[1]:.2f} m in the plan): a self-intersecting polygon is not a "
                            "walkable area; split it into polygons that do not cross themselves")


def plan_from_geojson(doc: dict, *, name: str = "", source: str | None = None,
                      max_ring_vertices: int = MAX_RING_VERTICES, max_vertices: int = MAX_PLAN_VERTICES) -> FloorPlan:
    """A :class:`FloorPlan` from a parsed GeoJSON document of our format (module docstring).

    The document is checked first (:class:`PlanFileError`, one line naming ``source`` and the feature): its
    structure, every position a pair of finite numbers, rings of 3 or more, at most ``max_ring_vertices`` in a
    ring or line and ``max_vertices`` in all, and walkable and obstacle rings that do not cross themselves."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise PlanFileError(f"{_where(source)}a floor plan is a GeoJSON FeatureCollection")
    head = doc.get("pdr_floorplan") or {}
    if not isinstance(head, dict):
        raise PlanFileError(f"{_where(source)}'pdr_floorplan' must be a JSON object")
    units = head.get("units", "deg")
    if units not in ("deg", "m"):
        raise PlanFileError(f"{_where(source)}pdr_floorplan.units must be 'deg' or 'm', not {str(units)[:20]!r}")
    for key, n in (("origin_lat_lon", 2), ("scale", 2)):
        v = head.get(key)
        if v is not None and not (isinstance(v, list) and len(v) == n and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)):
            raise PlanFileError(f"{_where(source)}pdr_floorplan.{key} must be {n} finite numbers")
    rot = head.get("rotation_deg", 0.0)
    if isinstance(rot, bool) or not isinstance(rot, (int, float)) or not math.isfinite(rot):
        raise PlanFileError(f"{_where(source)}pdr_floorplan.rotation_deg must be a finite number")
    feats = _features(doc, source, max_ring_vertices, max_vertices)
    if units == "deg":
        origin = head.get("origin_lat_lon")
        if origin is None:
            pts = [r for _, _, polys, lines in feats for p in polys for r in p] + [a for f in feats for a in f[3]]
            if not pts:
                raise PlanFileError(f"{_where(source)}a floor plan in degrees needs at least one coordinate")
            c = np.vstack(pts)
            lo, hi = c.min(axis=0), c.max(axis=0)
            origin = (0.5 * (lo[1] + hi[1]), 0.5 * (lo[0] + hi[0]))
        georef = Georeference(float(origin[0]), float(origin[1]))

        def conv(a):
            e, n = geodetic_to_enu(a[:, 1], a[:, 0], georef.origin)
            return np.column_stack([e, n])
    else:
        origin = head.get("origin_lat_lon")
        scale = head.get("scale", (1.0, 1.0))
        georef = None if origin is None else Georeference(
            float(origin[0]), float(origin[1]), math.radians(float(rot)), float(scale[0]), float(scale[1]))

        def conv(a):
            return a
    areas, obstacles, walls = [], [], []
    for i, kind, polys, lines in feats:
        where = _where(source, i)
        if kind == "walkable":
            for k, p in enumerate(polys):
                rings = [conv(r) for r in p]
                for j, r in enumerate(rings):
                    _check_simple(r, f"walkable polygon {k}, ring {j},", where)
                areas.append((rings[0], rings[1:]))
        elif kind == "obstacle":
            for k, p in enumerate(polys):
                r = conv(p[0])
                _check_simple(r, f"obstacle polygon {k}", where)
                obstacles.append(r)
        else:
            for line in lines:
                a = conv(line)
                walls.append(np.column_stack([a[:-1], a[1:]]))
            for p in polys:  # a polygon drawn as a wall: its rings are walls
                walls += [ring_segments(conv(r)) for r in p]
    return FloorPlan(areas=areas, obstacles=obstacles,
                     wall_lines=np.vstack(walls) if walls else np.zeros((0, 4)), georef=georef,
                     name=str(head.get("name", name)), floor=str(head.get("floor", "")))


def _load_json(source: str, max_bytes: int = MAX_PLAN_BYTES):
    """The parsed JSON of a map file (gzip by its name), or a :class:`PlanFileError` naming it: a file that
    cannot be read, is not JSON, or holds more than ``max_bytes`` of text (refused before it is parsed)."""
    try:
        with _open_text(source) as fh:
            text = fh.read(max_bytes + 1)
    except (OSError, EOFError, UnicodeDecodeError) as e:
        raise PlanFileError(f"{source}: cannot read the plan: {getattr(e, 'strerror', None) or e}") from None
    if len(text) > max_bytes:
        raise PlanFileError(f"{source}: the plan is over {max_bytes >> 20} MiB of text (the limit, "
                            "core.indoor.floorplan.MAX_PLAN_BYTES): simplify it or split it into floors")
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise PlanFileError(f"{source}: not JSON: {e.msg} at line {e.lineno} column {e.colno}") from None
    except RecursionError:
        raise PlanFileError(f"{source}: not JSON: nested too deeply") from None


def read_geojson(path, *, max_bytes: int = MAX_PLAN_BYTES, max_ring_vertices: int = MAX_RING_VERTICES,
                 max_vertices: int = MAX_PLAN_VERTICES) -> FloorPlan:
    """Read a floor plan of our GeoJSON format (``.geojson``, ``.json``, optionally ``.gz``).

    Whatever is wrong with the file is a :class:`PlanFileError` naming it (and the feature): a file that
    cannot be read, is not JSON, holds more than ``max_bytes`` of text (refused before it is parsed), or
    fails the checks of :func:`plan_from_geojson`."""
    source = str(path)
    doc = _load_json(source, max_bytes)
    return plan_from_geojson(doc, name=Path(source).name.split(".")[0], source=source,
                             max_ring_vertices=max_ring_vertices, max_vertices=max_vertices)


def _closed(ring) -> list:
    r = [list(map(float, p)) for p in ring]
    return r + [r[0]]


def plan_to_geojson(plan: FloorPlan, units: str = "m") -> dict:
    """Our GeoJSON document of a plan: ``units="m"`` (plan metres) or ``"deg"`` (WGS-84, needs the georeference)."""
    if units not in ("m", "deg"):
        raise ValueError("units must be 'm' or 'deg'")
    g = plan.georef
    if units == "deg":
        if g is None:
            raise ValueError("writing degrees needs the plan's georeference")

        def conv(a):
            lat, lon = g.to_geodetic(np.asarray(a, dtype=float).reshape(-1, 2))
            return np.column_stack([lon, lat])
    else:
        def conv(a):
            return np.asarray(a, dtype=float).reshape(-1, 2)
    head = {"version": FORMAT_VERSION, "units": units, "name": plan.name, "floor": plan.floor}
    if g is not None:
        head["origin_lat_lon"] = [g.origin_lat_deg, g.origin_lon_deg]
        if units == "m":
            head["rotation_deg"] = math.degrees(g.rotation_rad)
            head["scale"] = [g.scale_east, g.scale_north]
    feats = []
    for outer, holes in plan.areas:
        feats.append({"type": "Feature", "properties": {"kind": "walkable"},
                      "geometry": {"type": "Polygon", "coordinates": [_closed(conv(outer))]
                                   + [_closed(conv(h)) for h in holes]}})
    for r in plan.obstacles:
        feats.append({"type": "Feature", "properties": {"kind": "obstacle"},
                      "geometry": {"type": "Polygon", "coordinates": [_closed(conv(r))]}})
    if len(plan.wall_lines):
        lines = [conv(w.reshape(2, 2)).tolist() for w in plan.wall_lines]
        feats.append({"type": "Feature", "properties": {"kind": "wall"},
                      "geometry": {"type": "MultiLineString", "coordinates": lines}})
    return {"type": "FeatureCollection", "pdr_floorplan": head, "features": feats}


def write_geojson(plan: FloorPlan, path, units: str = "m") -> None:
    """Write a plan in our GeoJSON format (see :func:`plan_to_geojson`); ``.gz`` paths are gzip-compressed."""
    text = json.dumps(plan_to_geojson(plan, units))
    if str(path).endswith(".gz"):
        with gzip.open(str(path), "wt", encoding="utf-8") as fh:
            fh.write(text)
    else:
        Path(path).write_text(text, encoding="utf-8")


# ---------------------------------------------------------------------------
# Microsoft indoor location 2020


def _first(folder: Path, names) -> Path:
    for n in names:
        if (folder / n).exists():
            return folder / n
    raise FileNotFoundError(f"none of {', '.join(names)} in {folder}")


def read_ms_floor(folder) -> FloorPlan:
    """The Microsoft competition's floor map (``geojson_map.json(.gz)`` + ``floor_info.json``) in its waypoint metres."""
    folder = Path(folder)
    map_path = str(_first(folder, ("geojson_map.json", "geojson_map.json.gz")))
    doc = _load_json(map_path)
    info_path = str(_first(folder, ("floor_info.json", "floor_info.json.gz")))
    info = _load_json(info_path)
    info = info.get("map_info") if isinstance(info, dict) else None
    if not (isinstance(info, dict) and all(isinstance(info.get(k), (int, float)) and not isinstance(info.get(k), bool)
                                           and info[k] > 0 for k in ("width", "height"))):
        raise PlanFileError(f"{info_path}: needs 'map_info' with a positive 'width' and 'height' (m)")
    if not isinstance(doc, dict):
        raise PlanFileError(f"{map_path}: a floor map is a GeoJSON FeatureCollection")
    _features(doc, map_path, MAX_RING_VERTICES, MAX_PLAN_VERTICES)  # the structure, named file and feature
    feats = doc.get("features", [])
    if not feats:
        raise PlanFileError(f"{map_path}: the map has no features")
    c = _coords(doc)
    if not len(c):
        raise PlanFileError(f"{map_path}: the map has no coordinates")
    lon0, lat0 = c.min(axis=0)
    lon1, lat1 = c.max(axis=0)
    origin = (float(lat0), float(lon0))
    width_e, _ = geodetic_to_enu(lat0, lon1, origin)
    _, height_n = geodetic_to_enu(lat1, lon0, origin)
    sx = float(info["width"]) / float(width_e)
    sy = float(info["height"]) / float(height_n)
    georef = Georeference(origin[0], origin[1], 0.0, 1.0 / sx, 1.0 / sy)

    def conv(ring):
        a = np.asarray(ring, dtype=float)[:, :2]
        e, n = geodetic_to_enu(a[:, 1], a[:, 0], origin)
        return np.column_stack([np.asarray(e) * sx, np.asarray(n) * sy])

    areas = [(conv(p[0]), [conv(h) for h in p[1:]]) for p in _polygons(feats[0].get("geometry") or {})]
    obstacles = [conv(p[0]) for f in feats[1:] for p in _polygons(f.get("geometry") or {})]
    floor = str((feats[0].get("properties") or {}).get("floor", folder.name))
    return FloorPlan(areas=areas, obstacles=obstacles, georef=georef, name=f"{folder.parent.name}/{folder.name}",
                     floor=floor)


# ---------------------------------------------------------------------------
# IPIN (GetSensorData) floor images


@dataclass(frozen=True)
class ImageCalibration:
    """One floor image's georeference from a ``.cal`` file."""

    image: str
    floor: int
    building: int
    center_lat_deg: float
    center_lon_deg: float
    rotation_deg: float
    m_per_px: float


def read_ipin_cal(path) -> dict:
    """``{floor: ImageCalibration}`` from a GetSensorData ``.cal`` file (``%`` comments, then 7 rows)."""
    rows = []
    with _open_text(path) as fh:
        for line in fh:
            line = line.split("%", 1)[0].strip()
            if line:
                rows.append(line.split())
    if len(rows) != 7 or len({len(r) for r in rows}) != 1:
        raise ValueError(f"{path}: a .cal file has 7 rows of one value per floor, found {len(rows)} rows")
    out = {}
    for k in range(len(rows[0])):
        cal = ImageCalibration(rows[0][k], int(float(rows[1][k])), int(float(rows[2][k])), float(rows[3][k]),
                               float(rows[4][k]), float(rows[5][k]), float(rows[6][k]))
        if not (cal.m_per_px > 0 and all(math.isfinite(v) for v in (cal.center_lat_deg, cal.center_lon_deg,
                                                                    cal.rotation_deg))):
            raise ValueError(f"{path}: bad calibration of {cal.image}")
        out[cal.floor] = cal
    return out


def image_georeference(cal: ImageCalibration, shape_px) -> Georeference:
    """The georeference of a plan in image metres (x right, y up, origin at the image centre).

    The ``.cal`` rotation is the angle (deg) by which the image is turned from
    north-up; the plan's ENU is the image frame turned back by it, i.e.
    counter-clockwise by ``-rotation_deg`` (sign checked against the IPIN
    routes' landmarks on floor -1: docs/indoor.md).
    """
    return Georeference(cal.center_lat_deg, cal.center_lon_deg, math.radians(-cal.rotation_deg))


def read_ipin_floor(folder, floor: int, cal_name: str | None = None, *, read_image, **extract) -> FloorPlan:
    """The floor ``floor`` of an IPIN ``floormaps`` folder: walls from its image, georeferenced by the ``.cal``.

    ``read_image``: ``path -> grey array (rows, cols)``, e.g. :func:`desktop.floor_images.read_floor_image`
    (Pillow, desktop; ``core`` decodes no images).  ``extract``: keyword arguments of
    :func:`core.indoor.raster.walls_from_image`.
    """
    from core.indoor.raster import walls_from_image

    folder = Path(folder)
    cal_path = folder / cal_name if cal_name else next(iter(sorted(folder.glob("*.cal"))), None)
    if cal_path is None:
        raise FileNotFoundError(f"no .cal file in {folder}")
    cals = read_ipin_cal(cal_path)
    if floor not in cals:
        raise KeyError(f"{cal_path.name} has no floor {floor} (floors: {sorted(cals)})")
    cal = cals[floor]
    gray = read_image(folder / cal.image)
    h, w = gray.shape
    walls = walls_from_image(gray, cal.m_per_px, origin_px=(w / 2.0, h / 2.0), **extract)
    return FloorPlan(wall_lines=walls, georef=image_georeference(cal, gray.shape), name=cal.image.rsplit(".", 1)[0],
                     floor=str(floor))
