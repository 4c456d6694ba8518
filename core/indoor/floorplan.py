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
from core.indoor.geometry import WallGrid, points_in_polygon, ring_segments
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

    def is_walkable(self, xy) -> np.ndarray:
        """Boolean ``(N,)``: inside a walkable polygon, outside its holes and every obstacle."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not self.areas:
            ok = np.ones(len(p), dtype=bool)
        else:
            ok = np.zeros(len(p), dtype=bool)
            for outer, holes in self.areas:
                inside = points_in_polygon(p, outer)
                for h in holes:
                    inside &= ~points_in_polygon(p, h)
                ok |= inside
        for r in self.obstacles:
            ok &= ~points_in_polygon(p, r)
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


def plan_from_geojson(doc: dict, *, name: str = "") -> FloorPlan:
    """A :class:`FloorPlan` from a parsed GeoJSON document of our format (module docstring)."""
    if doc.get("type") != "FeatureCollection":
        raise ValueError("a floor plan is a GeoJSON FeatureCollection")
    head = doc.get("pdr_floorplan") or {}
    units = head.get("units", "deg")
    if units not in ("deg", "m"):
        raise ValueError(f"pdr_floorplan.units must be 'deg' or 'm', not {units!r}")
    if units == "deg":
        origin = head.get("origin_lat_lon")
        if origin is None:
            c = _coords(doc)
            if not len(c):
                raise ValueError("a floor plan in degrees needs at least one coordinate")
            lo, hi = c.min(axis=0), c.max(axis=0)
            origin = (0.5 * (lo[1] + hi[1]), 0.5 * (lo[0] + hi[0]))
        georef = Georeference(float(origin[0]), float(origin[1]))

        def conv(c):
            a = np.asarray(c, dtype=float)[:, :2]
            e, n = geodetic_to_enu(a[:, 1], a[:, 0], georef.origin)
            return np.column_stack([e, n])
    else:
        origin = head.get("origin_lat_lon")
        scale = head.get("scale", (1.0, 1.0))
        georef = None if origin is None else Georeference(
            float(origin[0]), float(origin[1]), math.radians(float(head.get("rotation_deg", 0.0))),
            float(scale[0]), float(scale[1]))

        def conv(c):
            return np.asarray(c, dtype=float)[:, :2]
    areas, obstacles, walls = [], [], []
    for f in doc.get("features", []):
        g = f.get("geometry") or {}
        kind = (f.get("properties") or {}).get("kind")
        polys, lines = _polygons(g), _lines(g)
        if kind is None:
            kind = "walkable" if polys else "wall"
        if kind not in KINDS:
            raise ValueError(f"unknown feature kind {kind!r} (one of {', '.join(KINDS)})")
        if kind == "walkable":
            areas += [(conv(p[0]), [conv(h) for h in p[1:]]) for p in polys]
        elif kind == "obstacle":
            obstacles += [conv(r) for p in polys for r in p[:1]]
        else:
            for line in lines:
                a = conv(line)
                walls.append(np.column_stack([a[:-1], a[1:]]))
            for p in polys:  # a polygon drawn as a wall: its rings are walls
                walls += [ring_segments(conv(r)) for r in p]
    return FloorPlan(areas=areas, obstacles=obstacles,
                     wall_lines=np.vstack(walls) if walls else np.zeros((0, 4)), georef=georef,
                     name=str(head.get("name", name)), floor=str(head.get("floor", "")))


def read_geojson(path) -> FloorPlan:
    """Read a floor plan of our GeoJSON format (``.geojson``, ``.json``, optionally ``.gz``)."""
    with _open_text(path) as fh:
        doc = json.load(fh)
    return plan_from_geojson(doc, name=Path(str(path)).name.split(".")[0])


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
    with _open_text(_first(folder, ("geojson_map.json", "geojson_map.json.gz"))) as fh:
        doc = json.load(fh)
    with _open_text(_first(folder, ("floor_info.json", "floor_info.json.gz"))) as fh:
        info = json.load(fh)["map_info"]
    feats = doc.get("features", [])
    if not feats:
        raise ValueError(f"{folder}: the map has no features")
    c = _coords(doc)
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
