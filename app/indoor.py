"""The floor plan in the app (issue #16, item 4), without Kivy: choosing a plan, and the particle filter of
:mod:`core.indoor` beside the session's tracker.

Plans the app reads (:func:`load_plan`)
    Our GeoJSON file (``.geojson``, ``.json``, ``.gz``: :func:`core.indoor.read_geojson`) or a Microsoft
    indoor floor folder (the folder holding ``floor_info.json``: :func:`core.indoor.read_ms_floor`).  Both
    need only ``json``, so they work on the phone.  An IPIN floor-image folder (a ``.cal`` and PNGs) needs
    Pillow to decode its images (desktop only): it is refused with the way out, which is to extract the walls
    on the desktop once and ship our GeoJSON (``core.indoor.write_geojson``; docs/indoor.md).

The frame
    With a plan the track view's metres are the **plan's** metres: walls, the map-matched track, the position
    and a tap are all in that frame.  The raw (dead-reckoned) track keeps its own frame (it starts at 0, 0);
    once placed, the view shifts it by :attr:`MapMatcher.raw_offset` so that its point at the placement lies on
    the placement point.

:class:`MapMatcher`
    One :class:`core.indoor.ParticleFilter` (the default :class:`~core.indoor.ParticleConfig`, 500
    particles) and what the app shows and exports of it.  It starts at the user's "I am here" tap
    (:meth:`MapMatcher.here`: the first one starts the filter with :data:`PLACE_SD_M`, every later one is a
    fix with :data:`FIX_SD_M`, a finger on a phone) or at a replayed recording's first landmark in plan
    metres (:meth:`MapMatcher.start_at`, as ``pdr replay --map`` does).  Every completed step after the
    placement goes to ``pf.update(step)``; steps walked before it (their peak time is not later than the
    placement) are not used, as in :func:`core.indoor.map_match`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.indoor import ParticleConfig, ParticleFilter, read_geojson, read_ms_floor

#: the file chooser's filters for a plan file (a Microsoft floor is chosen as its folder)
PLAN_PATTERNS = ["*.geojson", "*.json", "*.gz"]
#: sd of the first "I am here" tap (m): it starts the filter
PLACE_SD_M = 2.0
#: sd of a later "I am here" tap (m): a fix (a fingertip on a phone screen at a few px/m)
FIX_SD_M = 2.0
#: sd of a recording's landmark used as the start (m), as pdr replay --map
LANDMARK_SD_M = 1.0


def load_plan(path: str):
    """The :class:`core.indoor.FloorPlan` at ``path`` (see the module docstring); ValueError with a sentence."""
    p = Path(path)
    if p.is_dir():
        if any(p.glob("floor_info.json*")):
            return read_ms_floor(p)
        if any(p.glob("*.cal")):
            raise ValueError(f"{p.name}: an IPIN floor-image folder needs Pillow (desktop only); extract its "
                             "walls on the desktop and choose the GeoJSON (core.indoor.write_geojson)")
        raise ValueError(f"{p.name}: a folder without floor_info.json (a Microsoft floor)")
    if not p.exists():
        raise ValueError(f"{path}: no such file")
    try:
        return read_geojson(p)
    except (ValueError, OSError, KeyError, TypeError, AttributeError) as e:  # bad JSON, not our format
        raise ValueError(f"{p.name}: not a floor plan ({e})") from e


def plan_label(plan, path: str = "") -> str:
    """A plan's short name for the UI: its name (and floor), else the file or folder name."""
    name = plan.name or (Path(path).name if path else "plan")
    return f"{name} (floor {plan.floor})" if plan.floor else name


@dataclass(frozen=True)
class MapOverlay:
    """What the track view draws of the map matching (plain data; the lists are the matcher's, append-only)."""

    east: list  #: the map-matched track (plan metres): the placement, then one point per step or fix
    north: list
    position: tuple | None  #: the estimate (plan metres), None before the placement
    cov: tuple | None  #: its 2x2 covariance ((xx, xy), (xy, yy)), m^2
    raw_offset: tuple  #: plan metres minus raw-track metres (0, 0 before the placement)
    placed: bool
    text: str  #: the health panel's line
    bias_rad: float = 0.0  #: the filter's estimate of the heading error (measured - true), rad


class MapMatcher:
    """A particle filter on a plan beside the tracker, one row per session step (see the module docstring)."""

    def __init__(self, plan, *, name: str = "", steps_before: int = 0, config: ParticleConfig | None = None,
                 seed: int = 0):
        self.plan = plan
        self.name = name or plan_label(plan)
        self.pf = ParticleFilter(plan, config, seed=seed)
        self.east: list = []
        self.north: list = []
        #: per session step: map-matched east, north and spread (nan before the placement)
        self.step_east: list = [math.nan] * steps_before
        self.step_north: list = [math.nan] * steps_before
        self.step_spread: list = [math.nan] * steps_before
        self.est = None
        self.raw_offset = (0.0, 0.0)
        self._pending = None  # (t_ns, east, north, sd): start when the steps pass t_ns (a recording's landmark)
        self._raw_last = (0.0, 0.0)  # the raw track's last point (for the offset at the placement)
        self._start_xy = (0.0, 0.0, 0)  # where and when the filter started
        self.taps = 0
        self.update_s = 0.0  #: time spent in pf.update (s), for the health panel's ms/step

    @property
    def placed(self) -> bool:
        return self.pf.started

    def start_at(self, t_ns: int, east: float, north: float, sd: float = LANDMARK_SD_M) -> None:
        """Start the filter at ``(east, north)`` (plan metres) at sensor time ``t_ns``: now if the steps are
        there, else when the first step after ``t_ns`` comes."""
        self._pending = (int(t_ns), float(east), float(north), float(sd))

    def here(self, t_ns: int, east: float, north: float) -> None:
        """The user's "I am here" at plan ``(east, north)``: the start, then fixes."""
        self.taps += 1
        self._pending = None
        if self.pf.started:
            self._take(self.pf.fix(int(t_ns), float(east), float(north), FIX_SD_M))
        else:
            self._start(int(t_ns), float(east), float(north), PLACE_SD_M)

    def _start(self, t_ns: int, east: float, north: float, sd: float) -> None:
        self.east.clear()  # the lists are drawn as they grow: cleared, not replaced
        self.north.clear()
        self.raw_offset = (east - self._raw_last[0], north - self._raw_last[1])
        self._start_xy = (east, north, t_ns)
        self._take(self.pf.start(t_ns, east, north, sd))

    def _take(self, est) -> None:
        self.est = est
        self.east.append(est.east_m)
        self.north.append(est.north_m)

    def add_step(self, step) -> None:
        """A completed step of the session (one row, map-matched or nan)."""
        if not self.pf.started and self._pending is not None and step.t_ns > self._pending[0]:
            t, e, n, sd = self._pending
            self._pending = None
            self._start(t, e, n, sd)
        if self.pf.started and step.t_ns > self.pf.t_ns:
            t0 = time.perf_counter()
            est = self.pf.update(step)
            self.update_s += time.perf_counter() - t0
            self._take(est)
            self.step_east.append(est.east_m)
            self.step_north.append(est.north_m)
            self.step_spread.append(est.spread_m)
        else:
            if self.pf.started and step.t_ns <= self._start_xy[2]:  # walked before the placement, completed after
                self.raw_offset = (self._start_xy[0] - float(step.east_m), self._start_xy[1] - float(step.north_m))
            self.step_east.append(math.nan)
            self.step_north.append(math.nan)
            self.step_spread.append(math.nan)
        self._raw_last = (float(step.east_m), float(step.north_m))

    def overlay(self) -> MapOverlay:
        e = self.est
        return MapOverlay(self.east, self.north, (e.east_m, e.north_m) if e is not None else None,
                          e.cov if e is not None else None, self.raw_offset, self.placed, self.text(),
                          e.bias_rad if e is not None else 0.0)

    def text(self) -> str:
        """The health panel's line: where the filter is and its diagnostics (recoveries: the map disagrees)."""
        if not self.placed:
            return (f"map {self.name}: not placed (press 'Here', then tap where you are)"
                    if self._pending is None else f"map {self.name}: starts at the recording's first landmark")
        d, e = self.pf.diagnostics, self.est
        ms = 1000.0 * self.update_s / d.steps if d.steps else 0.0
        min_ess = f"{d.min_ess:.0f}" if math.isfinite(d.min_ess) else "-"
        return (f"map {self.name}: {d.steps} steps, ±{e.spread_m:.1f} m, bias {math.degrees(e.bias_rad):+.0f}°, "
                f"ESS {e.ess:.0f} (min {min_ess}) of {len(self.pf.w)}\n"
                f"map: {d.fixes} fixes ({d.fix_resets} resets), {d.recoveries} recoveries, {d.deaths} wall hits, "
                f"{ms:.1f} ms/step")

    def export_properties(self, t_ns, step_t_ns) -> dict:
        """Per-point properties of an export whose points have times ``t_ns``: the map-matched position of the
        session step with that time (``step_t_ns``: the session's steps' times), None where there is none;
        with a georeferenced plan also its latitude/longitude."""
        row = {int(t): k for k, t in enumerate(step_t_ns)}
        ks = [row.get(int(t)) for t in t_ns]

        def col(values, nd):
            return [None if k is None or not math.isfinite(values[k]) else round(float(values[k]), nd) for k in ks]

        out = {"mm_east_m": col(self.step_east, 3), "mm_north_m": col(self.step_north, 3),
               "mm_spread_m": col(self.step_spread, 3)}
        g = self.plan.georef
        if g is not None:
            xy = np.array([[e if e is not None else math.nan, n if n is not None else math.nan]
                           for e, n in zip(out["mm_east_m"], out["mm_north_m"])], dtype=float).reshape(-1, 2)
            lat, lon = g.to_geodetic(xy) if len(xy) else ([], [])
            out["mm_lat_deg"] = [round(float(v), 8) if math.isfinite(v) else None for v in lat]
            out["mm_lon_deg"] = [round(float(v), 8) if math.isfinite(v) else None for v in lon]
        return out
