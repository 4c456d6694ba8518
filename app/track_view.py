"""The live track widget (Kivy): track line, start marker, position and heading arrow, scale bar, GPS layer.

Pan with one finger (or the mouse), pinch with two fingers or the scroll
wheel to zoom, double-tap to fit the whole track.  Panning turns *follow*
off; the Follow button turns it on again (the view then keeps the current
position in the middle).

The track is kept in metres: its lines are drawn in metres under one
``PushMatrix``/``Translate``/``Scale`` pair that the
:class:`app.viewport.Viewport` sets, so following the walker and panning
move the whole track by changing two numbers, not by re-projecting and
re-tessellating every point (issue #14, item 3).  Each line is a
:class:`ChunkedLine`: ``Line`` instructions of :data:`LINE_CHUNK` points; a
new step rebuilds only the last chunk, so a step costs the same at 1 000
and at 50 000 points (``benchmarks/app_trackview.py``).  Only a zoom
rebuilds every chunk (the width, in metres, is the pixel width over the
scale).  Redraws are coalesced with a Clock trigger.

GPS layer (:meth:`TrackView.set_gps`, an :class:`app.session.GpsOverlay`)
    Once a fix has anchored the walk: the fused track (gold; its
    dead-reckoning-only stretches, ``source == "dr"``, violet), the raw PDR
    track thin and faint under it, the fixes as small squares (light grey;
    rejected ones red) with faint accuracy circles of radius ``hacc_m`` for
    the last :data:`MAX_ACCURACY_CIRCLES` fixes, the **2-sigma** uncertainty
    ellipse of the last fused step at the current position
    (:data:`app.overlay.ELLIPSE_SIGMA`), and a legend with
    "GPS: n fixes, m used · ±X m (2σ)", X the ellipse's semi-major axis.
    The number of canvas instructions hardly grows with the walk: all
    circles are one mesh per colour; the fixes are meshes of
    :data:`FIX_CHUNK` fixes each, under one ``Translate`` (the last
    :data:`MAX_FIX_CHUNKS` chunks), so a pan, and following the walker,
    moves them without touching a vertex, and a new fix rebuilds only its
    own chunk (the squares are rebuilt only when the zoom changes); the
    violet stretches are one line each.

Floor plan (:meth:`TrackView.set_plan`, :meth:`TrackView.set_map`; issue #16)
    With a plan the view's metres are the plan's (:mod:`app.indoor`).  The walls (``plan.walls``) are
    static: they are built once per plan, in metres, as ``lines`` meshes of at most :data:`WALL_CHUNK`
    segments under the same kind of ``Translate``/``Scale`` as the tracks, so panning, following and
    zooming never touch them (one pixel wide, under everything else).  Once placed, the map-matched
    track (green) is drawn over the raw one (thin and faint, shifted by the matcher's ``raw_offset``
    so that it starts where the user placed it), the position marker is the filter's estimate and the
    ellipse its 2-sigma one (``est.cov``, :func:`app.overlay.covariance_ellipse`); the heading arrow is
    the tracker's heading less the filter's estimate of its bias.  **Here**: with
    :attr:`TrackView.place_mode` on, a tap (a touch that lifts within :data:`TAP_SLOP_DP` of where it
    went down) fires ``on_here(east, north)`` in plan metres and turns the mode off; the app makes it
    the start or a fix.
"""

from __future__ import annotations

import math

import numpy as np
from kivy.clock import Clock
from kivy.graphics import (Color, Ellipse, InstructionGroup, Line, Mesh, PopMatrix, PushMatrix, Rectangle, Scale,
                           Translate, Triangle)
from kivy.metrics import dp, sp
from kivy.properties import BooleanProperty, NumericProperty, ObjectProperty
from kivy.uix.label import Label
from kivy.uix.widget import Widget

from app.overlay import (ELLIPSE_SIGMA, circles_mesh, covariance_ellipse, decimate, ellipse_points,  # noqa: F401
                         fan_mesh, gps_status_text, runs, squares_mesh)
from app.viewport import Viewport, format_length

BACKGROUND = (0.07, 0.08, 0.10, 1)
TRACK_COLOR = (0.15, 0.75, 1.0, 1)  #: the PDR (dead-reckoned) track
START_COLOR = (0.2, 0.85, 0.3, 1)
POSITION_COLOR = (1.0, 0.55, 0.1, 1)
BAR_COLOR = (0.92, 0.92, 0.92, 1)
GRID_COLOR = (0.16, 0.17, 0.20, 1)
FUSED_COLOR = (1.0, 0.84, 0.2, 1)  #: fused track, a fix accepted within the last few seconds
FUSED_DR_COLOR = (0.78, 0.45, 1.0, 1)  #: fused track, dead reckoning only (no fix accepted lately)
FIX_COLOR = (0.88, 0.90, 0.95, 1)  #: an accepted GPS fix
REJECTED_COLOR = (1.0, 0.25, 0.3, 1)  #: a fix the fusion did not use (screened out or gated)
RAW_UNDER_FUSED_ALPHA = 0.45  #: the PDR track's opacity under a fused track
CIRCLE_ALPHA = 0.22  #: accuracy circles
ELLIPSE_FILL_ALPHA = 0.2
MAX_ACCURACY_CIRCLES = 60  #: accuracy circles of the last fixes only (a minute at 1 Hz)
FIX_CHUNK = 500  #: fixes per mesh (per colour)
MAX_FIX_CHUNKS = 20  #: fix squares of the last 20 chunks only (10000 fixes: 2.8 h at 1 Hz)
WALL_COLOR = (0.55, 0.58, 0.66, 1)  #: the floor plan's walls
MAP_COLOR = (0.3, 0.95, 0.55, 1)  #: the map-matched track (the particle filter's estimate)
WALL_CHUNK = 16000  #: wall segments per Mesh (2 vertices each: below Kivy's 65 535 indices)
TAP_SLOP_DP = 12.0  #: a touch that lifts this close to where it went down is a tap (Here)
#: a zoom redraws the track with the points closer than this many pixels to the last one kept dropped (each
#: chunk keeps its first and last point): a whole walk fitted into the view tessellates a few points a chunk
DECIMATE_PX = 1.0
LINE_CHUNK = 100  #: track points per Line instruction (a new step rebuilds one; thick round-joined lines
#: tessellate at about 50 us a point on a desktop, so 100 points keep a step near 5 ms)


class ChunkedLine:
    """A polyline in metres (points ``start..end`` of two lists), drawn as ``Line`` instructions of at most
    ``chunk`` points in ``group``; consecutive chunks share their end point, so the line is continuous.

    :meth:`update` with the same lists, the same start and width and more points rebuilds only the last
    chunk and adds new ones, with no more points nothing; anything else (other lists: a new track; another
    width: a zoom) rebuilds all.  The lists must only grow (the session's do).
    """

    def __init__(self, group: InstructionGroup, chunk: int = LINE_CHUNK):
        self.group = group
        self.chunk = int(chunk)
        self.lines: list = []
        self._key = None  # (id(east), id(north), start, width) of what is drawn
        self.end = 0  # points start..end-1 are drawn
        self.rebuilt_chunks = 0  #: chunks (re)built by the last update (for tests and the benchmark)

    def clear(self) -> None:
        self.update([], [], 0, 0, 1.0)

    def update(self, east, north, start: int, end: int, width: float, tol_m: float = 0.0) -> None:
        """``tol_m``: drop the points closer than this to the last one kept (0: keep all); see :func:`decimate`."""
        if width == 1.0:  # Kivy draws width 1.0 as a 1-pixel GL line, which no Scale widens
            width = 1.0 + 1e-9
        key = (id(east), id(north), start, width, tol_m)
        first_chunk = 0
        if key == self._key and end == self.end:  # nothing new (the lists only ever grow)
            self.rebuilt_chunks = 0
            return
        if key == self._key and end > self.end:
            first_chunk = max((self.end - 1 - start) // self.chunk, 0) if self.end > start else 0
        self._key = key
        n = max(end - start, 0)
        n_chunks = -(-(n - 1) // self.chunk) if n > 1 else 0
        while len(self.lines) < n_chunks:
            line = Line(points=[], width=width, joint="round", cap="round")
            self.group.add(line)
            self.lines.append(line)
        self.rebuilt_chunks = 0
        for c in range(first_chunk, len(self.lines)):
            line = self.lines[c]
            if c < n_chunks:
                a = start + c * self.chunk
                b = min(a + self.chunk + 1, end)  # one point shared with the next chunk
                xs, ys = decimate(east[a:b], north[a:b], tol_m)
                pts = [0.0] * (2 * len(xs))
                pts[0::2] = xs
                pts[1::2] = ys
                line.width = width
                line.points = pts
                self.rebuilt_chunks += 1
            elif line.points:
                line.points = []
        self.end = end

    @property
    def n_points(self) -> int:
        """Points handed to the tessellator (shared chunk ends counted in each chunk)."""
        return sum(len(ln.points) // 2 for ln in self.lines)

    def points_m(self) -> list:
        """The drawn points (metres), ``[e0, n0, e1, n1, ...]``, each once."""
        out: list = []
        for k, line in enumerate(ln for ln in self.lines if ln.points):
            out.extend(line.points if k == 0 else line.points[2:])
        return out

    @property
    def width(self) -> float:
        return self._key[3] if self._key else 0.0


def _hex(rgba, alpha: float | None = None) -> str:
    r, g, b = (round(255 * v) for v in rgba[:3])
    a = round(255 * (rgba[3] if alpha is None else alpha))
    return f"#{r:02x}{g:02x}{b:02x}{a:02x}"


class TrackView(Widget):
    """Draws a track given in metres (East, North)."""

    follow = BooleanProperty(True)
    #: the next tap is "I am here" (on_here(east, north) in plan metres), then the mode turns off
    place_mode = BooleanProperty(False)
    #: the floor plan drawn (core.indoor.FloorPlan), None: none
    plan = ObjectProperty(None, allownone=True)
    #: track line width in pixels
    line_width = NumericProperty(dp(2))

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.vp = Viewport(scale=dp(12))
        self.east: list = [0.0]
        self.north: list = [0.0]
        self.position = (0.0, 0.0)
        self.heading_rad = math.nan
        self._touches: dict = {}
        self._line_dirty = True
        self._fixes_dirty = True
        self._moved = True  # the view moved (follow, pan): the world transform and the grid
        self.gps = None  # the last GpsOverlay given, None: GPS off
        self._fused_e: list = [0.0]  # the overlay's lists (append-only), points 0.._fused_len-1 drawn
        self._fused_n: list = [0.0]
        self._fused_len = 1
        self._fused_dr_runs: list = []
        self._dr_scanned = 0  # steps of the fused track scanned for dead-reckoning stretches
        self._fix = {"e": np.zeros(0), "n": np.zeros(0), "hacc": np.zeros(0), "ok": np.zeros(0, bool)}
        self.map = None  # the last app.indoor.MapOverlay given, None: no plan
        self._map_len = 0
        self.register_event_type("on_here")
        with self.canvas.before:
            Color(*BACKGROUND)
            self._bg = Rectangle(pos=self.pos, size=self.size)
            Color(*GRID_COLOR)
            self._grid = Mesh(vertices=[], indices=[], mode="lines")
        with self.canvas:
            # accuracy circles (faint), one mesh per colour
            self._circles, self._circle_colors, self._dots, self._dot_colors = {}, {}, {}, {}
            for key, rgba in (("accepted", FIX_COLOR), ("rejected", REJECTED_COLOR)):
                self._circle_colors[key] = Color(*rgba[:3], CIRCLE_ALPHA)
                self._circles[key] = Mesh(vertices=[], indices=[], mode="lines")
            # the floor plan's walls, in plan metres (static: built once per plan)
            self._plan_world = []  # (Translate, Scale) pairs of the plan frame
            PushMatrix()
            self._plan_world.append((Translate(0, 0), Scale(1, 1, 1)))
            self._wall_color = Color(*WALL_COLOR)
            self._walls = InstructionGroup()
            self.canvas.add(self._walls)
            PopMatrix()
            # the PDR track, in metres under the world transform (see the module docstring)
            self._world = []  # the (Translate, Scale) pairs the viewport sets (the raw frame: + raw_offset)
            PushMatrix()
            self._world.append((Translate(0, 0), Scale(1, 1, 1)))
            self._line_color = Color(*TRACK_COLOR)
            self._line = ChunkedLine(InstructionGroup())
            self.canvas.add(self._line.group)
            PopMatrix()
            # the fixes: small squares, chunks of FIX_CHUNK fixes per mesh and colour, shifted by _fix_shift
            PushMatrix()
            self._fix_shift = Translate(0, 0)
            self._fix_groups = {}
            for key, rgba in (("accepted", FIX_COLOR), ("rejected", REJECTED_COLOR)):
                self._dot_colors[key] = Color(*rgba)
                self._fix_groups[key] = InstructionGroup()
                self._dots[key] = []  # one Mesh per chunk
            PopMatrix()
            self._fix_built = None  # (scale, x, y): the scale and screen position of (0, 0) the squares are built at
            self._fix_first = 0  # the first chunk drawn
            self._fix_chunks_built = 0  # chunks up to date (all but the last, which takes the new fixes)
            PushMatrix()
            self._world.append((Translate(0, 0), Scale(1, 1, 1)))
            self._fused_color = Color(*FUSED_COLOR)
            self._fused = ChunkedLine(InstructionGroup())
            self.canvas.add(self._fused.group)
            self._fused_dr_color = Color(*FUSED_DR_COLOR)
            self._fused_dr = InstructionGroup()  # one ChunkedLine per dead-reckoning stretch (a pool, reused)
            self.canvas.add(self._fused_dr)
            self._fused_dr_lines: list = []
            PopMatrix()
            # the map-matched track, in plan metres
            PushMatrix()
            self._plan_world.append((Translate(0, 0), Scale(1, 1, 1)))
            self._map_color = Color(*MAP_COLOR)
            self._map_line = ChunkedLine(InstructionGroup())
            self.canvas.add(self._map_line.group)
            PopMatrix()
            Color(*START_COLOR)
            self._start = Ellipse(size=(0, 0))
            # the uncertainty ellipse (ELLIPSE_SIGMA, 2-sigma), under the position marker
            self._ellipse_fill_color = Color(*POSITION_COLOR[:3], ELLIPSE_FILL_ALPHA)
            self._ellipse_fill = Mesh(vertices=[], indices=[], mode="triangle_fan")
            self._ellipse_color = Color(*POSITION_COLOR)
            self._ellipse = Line(points=[], width=dp(1.2), close=True)
            Color(*POSITION_COLOR)
            self._arrow = Triangle(points=[0, 0, 0, 0, 0, 0])
            self._dot = Ellipse(size=(0, 0))
            Color(*BAR_COLOR)
            self._bar = Line(points=[], width=dp(1.5))
        self._bar_label = Label(text="", font_size=sp(12), color=BAR_COLOR, size_hint=(None, None))
        self.add_widget(self._bar_label)
        self._legend = Label(text="", font_size=sp(12), color=BAR_COLOR, size_hint=(None, None), markup=True,
                             halign="left", valign="top")
        with self._legend.canvas.before:
            Color(*BACKGROUND[:3], 0.75)
            self._legend_bg = Rectangle(size=(0, 0))
        self.add_widget(self._legend)
        self._trigger = Clock.create_trigger(self._redraw, 0)
        self.bind(pos=self._view_changed, size=self._view_changed, follow=self._view_changed)

    # -- data ---------------------------------------------------------------------

    def set_track(self, east, north) -> None:
        """The track: lists of metres, first point = the start.  The lists are kept, not copied: give the
        same lists again after appending to them (the session's own) and only the new points are drawn;
        other lists are a new track."""
        self.east = east if len(east) else [0.0]
        self.north = north if len(north) else [0.0]
        self.position = (self.east[-1], self.north[-1])
        self._line_dirty = True
        self._trigger()

    def set_heading(self, heading_rad: float) -> None:
        self.heading_rad = heading_rad
        self._trigger()

    def set_gps(self, gps) -> None:
        """The GPS layer: an :class:`app.session.GpsOverlay`, or None (GPS off).

        Cheap to call on every UI update: the overlay's lists only grow, and only what grew is
        copied and marked for redrawing.
        """
        old, self.gps = self.gps, gps
        if gps is None:
            self._fused_e, self._fused_n, self._fused_len = [0.0], [0.0], 1
            self._fused_dr_runs, self._dr_scanned = [], 0
            self._fix = {"e": np.zeros(0), "n": np.zeros(0), "hacc": np.zeros(0), "ok": np.zeros(0, bool)}
            self._line_dirty = self._fixes_dirty = True
            self._fix_built = None
        else:
            n_steps = len(gps.fused_source)
            new_track = old is None or old.fused_source is not gps.fused_source  # a new session or track
            if new_track or n_steps != self._fused_len - 1 or old.anchored != gps.anchored:
                self._fused_e, self._fused_n, self._fused_len = gps.fused_east, gps.fused_north, n_steps + 1
                if new_track:
                    self._fused_dr_runs, self._dr_scanned = [], 0
                self._scan_dr(gps.fused_source, n_steps)
                self._line_dirty = True
            n_fix = len(gps.fix_accepted)
            if new_track or n_fix < len(self._fix["ok"]):
                self._fix_built = None  # not the same fixes: every chunk anew
            if new_track or n_fix != len(self._fix["ok"]):
                self._fix = {"e": np.array(gps.fix_east[:n_fix], dtype=float),
                             "n": np.array(gps.fix_north[:n_fix], dtype=float),
                             "hacc": np.array(gps.fix_hacc[:n_fix], dtype=float),
                             "ok": np.array(gps.fix_accepted[:n_fix], dtype=bool)}
                self._fixes_dirty = True
        self._set_legend(self._legend_text())
        self._trigger()

    def set_plan(self, plan) -> None:
        """The floor plan under the track (None: none): its walls are built here, once."""
        self.plan = plan
        self._walls.clear()
        walls = np.asarray(plan.walls if plan is not None else np.zeros((0, 4)), dtype=float).reshape(-1, 4)
        for a in range(0, len(walls), WALL_CHUNK):
            seg = walls[a:a + WALL_CHUNK]
            verts = np.zeros((len(seg), 2, 4))
            verts[:, 0, :2], verts[:, 1, :2] = seg[:, :2], seg[:, 2:]
            self._walls.add(Mesh(vertices=verts.ravel().tolist(), indices=list(range(2 * len(seg))), mode="lines"))
        if plan is None:
            self.set_map(None)
        self._view_changed()

    @property
    def wall_meshes(self) -> list:
        """The walls' meshes (for tests): ``lines`` meshes in plan metres."""
        return [m for m in self._walls.children if isinstance(m, Mesh)]

    def set_map(self, overlay) -> None:
        """The map matching (:class:`app.indoor.MapOverlay`) or None; cheap to call on every UI update."""
        old, self.map = self.map, overlay
        n = len(overlay.east) if overlay is not None else 0
        if old is None or overlay is None or old.east is not overlay.east or n != self._map_len \
                or old.raw_offset != overlay.raw_offset:
            self._map_len = n
            self._line_dirty = True
            self._moved = True  # the raw frame's offset may have changed
        self._set_legend(self._legend_text())
        self._trigger()

    @property
    def raw_offset(self) -> tuple[float, float]:
        """Plan metres minus raw-track metres (0, 0 without a placed map)."""
        m = self.map
        return tuple(m.raw_offset) if m is not None and m.placed else (0.0, 0.0)

    @property
    def shows_map(self) -> bool:
        """A map-matched position is drawn (a plan, placed)."""
        return self.map is not None and self.map.placed and self.map.position is not None

    def on_here(self, east: float, north: float) -> None:
        """A tap in place mode, in plan metres (the app binds this)."""

    def _scan_dr(self, source, n_steps: int) -> None:
        """Extend the dead-reckoning stretches (:func:`app.overlay.runs` of ``source == "dr"``) by the new
        steps only: the last stretch grows, or new ones start."""
        new = runs([s == "dr" for s in source[self._dr_scanned:n_steps]])
        off = self._dr_scanned
        out = self._fused_dr_runs
        for a, b in new:
            a, b = a + off, b + off
            if out and a == out[-1][1] and a > 0 and source[a - 1] == "dr":
                out[-1] = (out[-1][0], b)  # the last stretch goes on
            else:
                out.append((a, b))
        self._dr_scanned = n_steps

    @property
    def shows_fused(self) -> bool:
        """A fused track is drawn (GPS on, the walk anchored by a fix, at least one step)."""
        return self.gps is not None and self.gps.anchored and self._fused_len > 1

    @property
    def current_position(self) -> tuple[float, float]:
        """Where the position marker is: the map-matched estimate when placed on a plan, else the fused track's
        end when there is one, else the PDR track's."""
        if self.shows_map:
            return tuple(float(v) for v in self.map.position)
        if self.shows_fused:
            k = self._fused_len - 1
            return float(self._fused_e[k]), float(self._fused_n[k])
        return self.position

    def fit(self, *_) -> None:
        """Show the whole track (and the fused one); turns follow off."""
        self.follow = False
        self.vp.set_rect(self.x, self.y, self.width, self.height)
        east, north = self.east, self.north
        if self.shows_fused:
            k = self._fused_len
            east, north = np.concatenate([east, self._fused_e[:k]]), np.concatenate([north, self._fused_n[:k]])
        if self.plan is not None:  # the plan's frame: the raw track shifted, the map-matched track; before the
            ox, oy = self.raw_offset  # placement the whole plan (to tap on)
            east, north = np.asarray(east, float) + ox, np.asarray(north, float) + oy
            if self.shows_map:
                east, north = np.concatenate([east, self.map.east]), np.concatenate([north, self.map.north])
            else:
                x0, y0, x1, y1 = self.plan.bounds()
                east, north = np.array([x0, x1]), np.array([y0, y1])
        self.vp.fit(east, north, margin_px=dp(48))  # clear of the button bar and scale bar
        self._view_changed()

    def _view_changed(self, *_):
        self._line_dirty = True  # a zoom or a new size: every chunk (the widths are in metres)
        self._fixes_dirty = True
        self._trigger()

    # -- drawing ----------------------------------------------------------------------

    def _redraw(self, *_):
        vp = self.vp
        vp.set_rect(self.x, self.y, self.width, self.height)
        self._bg.pos, self._bg.size = self.pos, self.size
        position = self.current_position
        if self.follow:
            old = vp.center
            vp.follow(*position)
            if old != vp.center:
                self._moved = True
        if self._moved or self._line_dirty:
            self._set_world()
            self._draw_grid()
            self._fixes_dirty = self._fixes_dirty or self._moved
            self._moved = False
        if self._line_dirty:
            fused = self.shows_fused
            under = fused or self.shows_map
            self._line_color.a = RAW_UNDER_FUSED_ALPHA if under else 1.0
            self._line.update(self.east, self.north, 0, len(self.east),
                              (dp(1) if under else self.line_width) / vp.scale, DECIMATE_PX / vp.scale)
            self._draw_fused(fused)
            m = self.map
            if m is not None and m.placed:
                self._map_line.update(m.east, m.north, 0, self._map_len, self.line_width / vp.scale)
            elif self._map_line.end:
                self._map_line.clear()
            self._line_dirty = False
        if self._fixes_dirty:
            self._draw_fixes()
            self._fixes_dirty = False
        r = dp(6)
        ox, oy = self.raw_offset
        sx, sy = vp.to_screen(self.east[0] + ox, self.north[0] + oy)
        self._start.pos, self._start.size = (sx - r, sy - r), (2 * r, 2 * r)
        px, py = vp.to_screen(*position)
        self._draw_ellipse(px, py)
        r = dp(5)
        self._dot.pos, self._dot.size = (px - r, py - r), (2 * r, 2 * r)
        h = self.heading_rad - (self.map.bias_rad if self.shows_map else 0.0)  # the map's heading correction
        if h == h:
            c, s = math.cos(h), math.sin(h)
            tip, back, half = dp(22), dp(4), dp(7)
            bx, by = px - back * c, py - back * s
            self._arrow.points = [px + tip * c, py + tip * s, bx - half * s, by + half * c, bx + half * s,
                                  by - half * c]
        else:
            self._arrow.points = [px, py, px, py, px, py]
        self._draw_scale_bar()
        self._place_legend()

    def _set_world(self) -> None:
        """The world transform: metres -> window pixels, as the viewport maps them."""
        vp = self.vp
        for pairs, origin in ((self._world, self.raw_offset), (self._plan_world, (0.0, 0.0))):
            tx, ty = vp.to_screen(*origin)
            for translate, scale in pairs:
                translate.xy = (tx, ty)
                scale.xyz = (vp.scale, vp.scale, 1.0)

    def _draw_fused(self, shown: bool) -> None:
        """The fused track, and its dead-reckoning-only stretches over it in their own colour."""
        width = self.line_width / self.vp.scale
        n = self._fused_len if shown else 0
        self._fused.update(self._fused_e, self._fused_n, 0, n, width)
        stretches = self._fused_dr_runs if shown else []
        lines = self._fused_dr_lines
        while len(lines) < len(stretches):
            lines.append(ChunkedLine(self._fused_dr))
        for k, line in enumerate(lines):
            if k < len(stretches):
                i0, i1 = stretches[k]
                line.update(self._fused_e, self._fused_n, i0, i1 + 1, width)
            elif line.end:
                line.clear()

    def to_screen_points(self, points_m) -> list:
        """Metres ``[e0, n0, ...]`` (what a :class:`ChunkedLine` holds) -> window pixels, as drawn."""
        pts = np.asarray(points_m, dtype=float).reshape(-1, 2)
        x, y = self.vp.to_screen_arrays(pts[:, 0], pts[:, 1])
        return np.c_[x, y].reshape(-1).tolist()

    def _draw_fixes(self) -> None:
        """Accuracy circles (the last MAX_ACCURACY_CIRCLES) and fix squares (see :meth:`_draw_fix_squares`)."""
        f = self._fix
        shown = self.shows_fused
        ok, hacc = f["ok"], f["hacc"]
        n = len(ok)
        recent = (np.arange(n) >= n - MAX_ACCURACY_CIRCLES) & np.isfinite(hacc) & (hacc > 0)
        if not shown:
            recent[:] = False
        ox, oy = self.raw_offset
        x, y = self.vp.to_screen_arrays(f["e"][recent] + ox, f["n"][recent] + oy)
        for key, mask in (("accepted", ok[recent]), ("rejected", ~ok[recent])):
            self._circles[key].vertices, self._circles[key].indices = circles_mesh(
                x[mask], y[mask], hacc[recent][mask] * self.vp.scale, n=32)
        self._draw_fix_squares(shown)

    def _draw_fix_squares(self, shown: bool) -> None:
        """The fixes as squares, FIX_CHUNK fixes per mesh and colour (the last MAX_FIX_CHUNKS chunks).

        The squares are built in the screen frame of the view when they were built (``_fix_built``);
        ``_fix_shift`` moves them to the current one.  A new zoom rebuilds them all, a new fix only the
        chunks from the last complete one on, a pan none.
        """
        vp, f = self.vp, self._fix
        n = len(f["ok"]) if shown else 0
        n_chunks = -(-n // FIX_CHUNK)
        first = max(n_chunks - MAX_FIX_CHUNKS, 0)
        ox, oy = vp.to_screen(*self.raw_offset)
        built = self._fix_built
        if built is None or built[0] != vp.scale or self._fix_first != first:
            built = self._fix_built = (vp.scale, ox, oy)
            self._fix_chunks_built = 0
            self._fix_first = first
        s, bx, by = built
        self._fix_shift.xy = (ox - bx, oy - by)
        for key, mask in (("accepted", f["ok"]), ("rejected", ~f["ok"])):
            meshes, group = self._dots[key], self._fix_groups[key]
            while len(meshes) < n_chunks - first:
                meshes.append(Mesh(vertices=[], indices=[], mode="triangles"))
                group.add(meshes[-1])
            for c in range(len(meshes)):
                k = first + c
                if k < self._fix_chunks_built and c < n_chunks - first:
                    continue  # complete and built at this scale
                sl = slice(k * FIX_CHUNK, min((k + 1) * FIX_CHUNK, n))
                m = mask[sl]
                x, y = bx + f["e"][sl][m] * s, by + f["n"][sl][m] * s
                drawn = c < n_chunks - first
                meshes[c].vertices, meshes[c].indices = squares_mesh(x, y, dp(1.6)) if drawn else ([], [])
        self._fix_chunks_built = max(n // FIX_CHUNK, first)  # the last, incomplete chunk is rebuilt next time

    def _draw_ellipse(self, px: float, py: float) -> None:
        """The ELLIPSE_SIGMA (2-sigma) ellipse of the position's covariance, in pixels: the particle filter's
        when placed on a plan, else the last fused step's."""
        cov = self.gps.cov_en_m2 if self.gps is not None and self.shows_fused else None
        if self.shows_map and self.map.cov is not None:
            (ve, c), (_, vn) = self.map.cov
            cov = (ve, c, vn)
        if cov is None:
            self._ellipse.points = []
            self._ellipse_fill.vertices, self._ellipse_fill.indices = [], []
            return
        a, b, angle = covariance_ellipse(cov, ELLIPSE_SIGMA)
        s = self.vp.scale
        outline = ellipse_points(px, py, a * s, b * s, angle, n=48)
        self._ellipse.points = outline
        self._ellipse_fill.vertices, self._ellipse_fill.indices = fan_mesh(px, py, outline)

    # -- the legend ---------------------------------------------------------------------

    def _legend_text(self) -> str:
        text = self._gps_legend()
        m = self.map
        if m is not None:
            if m.placed and m.cov is not None:
                (ve, c), (_, vn) = m.cov
                a, _, _ = covariance_ellipse((ve, c, vn), ELLIPSE_SIGMA)
                line = (f"[color={_hex(MAP_COLOR)}]—[/color] map · ±{a:.1f} m ({ELLIPSE_SIGMA:g}σ)   "
                        f"[color={_hex(WALL_COLOR)}]—[/color] walls")
            else:
                line = "map: press Here, then tap where you are"
            text = f"{text}\n{line}"
        return text

    def _gps_legend(self) -> str:
        g = self.gps
        if g is None:
            return "GPS off"
        text = gps_status_text(g.n_fixes, g.n_used, g.cov_en_m2, g.anchored, ELLIPSE_SIGMA, g.last_verdict)
        if g.anchored:
            def key(rgba, mark, label, alpha=None):
                return f"[color={_hex(rgba, alpha)}]{mark}[/color] {label}"
            text += "\n" + "   ".join((key(FUSED_COLOR, "—", "fused"), key(FUSED_DR_COLOR, "—", "no GPS"),
                                       key(TRACK_COLOR, "—", "PDR only", RAW_UNDER_FUSED_ALPHA)))
            text += "\n" + "   ".join((key(FIX_COLOR, "•", "fix, accuracy circle"),
                                       key(REJECTED_COLOR, "•", "rejected"),
                                       key(POSITION_COLOR, "o", f"{ELLIPSE_SIGMA:g}σ ellipse")))
        return text

    def _set_legend(self, text: str) -> None:
        lbl = self._legend
        if lbl.text != text:
            lbl.text = text
            lbl.texture_update()
            lbl.size = lbl.texture_size

    def _place_legend(self) -> None:
        lbl = self._legend
        lbl.pos = (self.x + dp(8), self.top - dp(46) - lbl.height)  # below the message bar of layout.kv
        pad = dp(3)
        self._legend_bg.pos = (lbl.x - pad, lbl.y - pad)
        self._legend_bg.size = (lbl.width + 2 * pad, lbl.height + 2 * pad) if lbl.text else (0, 0)

    def _draw_grid(self):
        """Faint lines every scale-bar length, aligned to the start (East/North axes)."""
        vp = self.vp
        step_m, step_px = vp.scale_bar(dp(120))
        segs = []
        if step_px >= dp(20) and step_m > 0:
            e0, n0 = vp.to_world(self.x, self.y)
            e1, n1 = vp.to_world(self.right, self.top)
            k = math.floor(e0 / step_m)
            while k * step_m <= e1:
                x, _ = vp.to_screen(k * step_m, 0)
                segs.append((x, self.y, x, self.top))
                k += 1
            k = math.floor(n0 / step_m)
            while k * step_m <= n1:
                _, y = vp.to_screen(0, k * step_m)
                segs.append((self.x, y, self.right, y))
                k += 1
        verts = []
        for x0, y0, x1, y1 in segs:
            verts += [x0, y0, 0, 0, x1, y1, 0, 0]
        self._grid.vertices = verts
        self._grid.indices = list(range(2 * len(segs)))

    def _draw_scale_bar(self):
        m, px = self.vp.scale_bar(dp(120))
        x0, y0 = self.x + dp(14), self.y + dp(14)
        tick = dp(5)
        self._bar.points = [x0, y0 + tick, x0, y0, x0 + px, y0, x0 + px, y0 + tick]
        lbl = self._bar_label
        text = format_length(m)
        if lbl.text != text or not lbl.texture:  # a new text texture only when the text changes (it costs
            lbl.text = text                      # tens of ms a frame on a software renderer)
            lbl.texture_update()
            lbl.size = lbl.texture_size
        lbl.pos = (x0, y0 + dp(4))

    # -- touch: pan, pinch, scroll, double tap ---------------------------------------------

    def on_touch_down(self, touch):
        if not self.collide_point(*touch.pos):
            return super().on_touch_down(touch)
        if getattr(touch, "is_mouse_scrolling", False):
            factor = 1.25 if touch.button == "scrolldown" else 1 / 1.25
            x, y = (self.center if self.follow else touch.pos)
            self.vp.zoom_at(factor, x, y)
            self._view_changed()
            return True
        if touch.is_double_tap:
            self.fit()
            return True
        touch.grab(self)
        self._touches[touch.uid] = touch.pos
        return True

    def on_touch_move(self, touch):
        if touch.grab_current is not self or touch.uid not in self._touches:
            return super().on_touch_move(touch)
        old = dict(self._touches)
        self._touches[touch.uid] = touch.pos
        if len(self._touches) == 1:
            ox, oy = old[touch.uid]
            self.follow = False
            self.vp.pan(touch.x - ox, touch.y - oy)
        else:
            a, b = list(self._touches)[:2]
            (ax0, ay0), (bx0, by0) = old[a], old[b]
            (ax1, ay1), (bx1, by1) = self._touches[a], self._touches[b]
            d0 = math.hypot(bx0 - ax0, by0 - ay0)
            d1 = math.hypot(bx1 - ax1, by1 - ay1)
            mx0, my0 = (ax0 + bx0) / 2, (ay0 + by0) / 2
            mx1, my1 = (ax1 + bx1) / 2, (ay1 + by1) / 2
            self.follow = False
            self.vp.pan(mx1 - mx0, my1 - my0)
            if d0 > 1 and d1 > 1:
                self.vp.zoom_at(d1 / d0, mx1, my1)
        self._view_changed()
        return True

    def on_touch_up(self, touch):
        if touch.grab_current is self:
            touch.ungrab(self)
            single = len(self._touches) == 1
            self._touches.pop(touch.uid, None)
            if self.place_mode and single and math.dist(touch.opos, touch.pos) <= dp(TAP_SLOP_DP):
                self.place_mode = False
                self.dispatch("on_here", *self.vp.to_world(*touch.pos))
            return True
        return super().on_touch_up(touch)
