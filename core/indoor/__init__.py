"""Indoors, the building is the reference: floor plans, a particle filter on the steps, landmark fixes.

numpy only (runs on the phone).  Modules:

``core.indoor.geometry``
    Segment intersection (CLRS 33.1), the wall grid, point in polygon.
``core.indoor.floorplan``
    :class:`FloorPlan` (walkable polygons, obstacles, wall lines in plan
    metres, :class:`Georeference` through :mod:`core.geodesy`) and its
    readers/writers: our GeoJSON format, the Microsoft indoor maps, the IPIN
    ``.cal`` floor images.
``core.indoor.raster``
    Walls from a floor image (Otsu threshold, boundary vectorisation).
``core.indoor.particles``
    :class:`ParticleFilter`: streaming ``update(step)`` / ``fix(...)`` and
    batch ``run(steps, fixes)`` on one kernel.

The one call for the CLI and the app is :func:`map_match`; docs/indoor.md
describes the format, the filter and the benchmark.
"""

from __future__ import annotations

from core.indoor.floorplan import (  # noqa: F401 - the package's API
    FloorPlan, Georeference, ImageCalibration, plan_from_geojson, plan_to_geojson, read_geojson, read_ipin_cal,
    read_ipin_floor, read_ms_floor, write_geojson,
)
from core.indoor.particles import (  # noqa: F401
    Diagnostics, Estimate, MapMatchResult, ParticleConfig, ParticleFilter, StepArrays, _step_arrays,
)


def map_match(steps, plan=None, *, start=None, start_gps=None, fixes=(), config: ParticleConfig | None = None,
              seed: int = 0, smooth: bool = False) -> MapMatchResult:
    """The map-matched track of a walk's steps.

    steps
        :class:`core.pdr.pipeline.Step` objects or a :class:`core.pdr.pipeline.Track`
        (anything with ``t_ns``, ``length_m``, ``heading_rad``), in time order.
    plan
        A :class:`FloorPlan` in the steps' frame (plan metres), or None (fixes only).
    start
        ``(t_ns, east_m, north_m, sd_m)``: a known start or a landmark, in plan metres.
    start_gps
        ``(t_ns, lat_deg, lon_deg, hacc_m)`` instead: a GPS fix placed by ``plan.georef``.
    fixes
        ``(t_ns, east_m, north_m, sd_m)`` tuples (taps on the map, surveyed landmarks).

    smooth
        Also the batch smoother's track (``result.smoothed_east_m/north_m``:
        the final particles' ancestral paths; for replays, not the live app).

    Steps before the start are not used.  Returns a :class:`MapMatchResult`
    (one row per step: position, covariance and spread, heading bias, ESS;
    ``diagnostics``).
    """
    pf = ParticleFilter(plan, config, seed=seed, keep_paths=smooth)
    if start is not None:
        t0 = int(start[0])
        pf.start(t0, float(start[1]), float(start[2]), float(start[3]))
    elif start_gps is not None:
        t0 = int(start_gps[0])
        pf.start_gps(t0, float(start_gps[1]), float(start_gps[2]), float(start_gps[3]))
    else:
        raise ValueError("map_match needs a start (a point or a GPS fix)")
    t, length, heading = _step_arrays(steps)
    keep = t > t0
    return pf.run(StepArrays(t[keep], length[keep], heading[keep]), [f for f in fixes if int(f[0]) >= t0])
