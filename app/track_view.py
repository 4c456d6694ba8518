"""The live track widget (Kivy): track line, start marker, position and heading arrow, scale bar.

Pan with one finger (or the mouse), pinch with two fingers or the scroll
wheel to zoom, double-tap to fit the whole track.  Panning turns *follow*
off; the Follow button turns it on again (the view then keeps the current
position in the middle).

The track is kept in metres and mapped to pixels by an
:class:`app.viewport.Viewport` (numpy, once per redraw), so the line width
stays constant on screen.  Redraws are coalesced with a Clock trigger: the
line is rebuilt only when the track or the view changed, the position
marker on every update.
"""

from __future__ import annotations

import math

from kivy.clock import Clock
from kivy.graphics import Color, Ellipse, Line, Mesh, Rectangle, Triangle
from kivy.metrics import dp, sp
from kivy.properties import BooleanProperty, NumericProperty
from kivy.uix.label import Label
from kivy.uix.widget import Widget

from app.viewport import Viewport, format_length

BACKGROUND = (0.07, 0.08, 0.10, 1)
TRACK_COLOR = (0.15, 0.75, 1.0, 1)
START_COLOR = (0.2, 0.85, 0.3, 1)
POSITION_COLOR = (1.0, 0.55, 0.1, 1)
BAR_COLOR = (0.92, 0.92, 0.92, 1)
GRID_COLOR = (0.16, 0.17, 0.20, 1)


class TrackView(Widget):
    """Draws a track given in metres (East, North)."""

    follow = BooleanProperty(True)
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
        with self.canvas.before:
            Color(*BACKGROUND)
            self._bg = Rectangle(pos=self.pos, size=self.size)
            Color(*GRID_COLOR)
            self._grid = Mesh(vertices=[], indices=[], mode="lines")
        with self.canvas:
            Color(*TRACK_COLOR)
            self._line = Line(points=[], width=self.line_width, joint="round", cap="round")
            Color(*START_COLOR)
            self._start = Ellipse(size=(0, 0))
            Color(*POSITION_COLOR)
            self._arrow = Triangle(points=[0, 0, 0, 0, 0, 0])
            self._dot = Ellipse(size=(0, 0))
            Color(*BAR_COLOR)
            self._bar = Line(points=[], width=dp(1.5))
        self._bar_label = Label(text="", font_size=sp(12), color=BAR_COLOR, size_hint=(None, None))
        self.add_widget(self._bar_label)
        self._trigger = Clock.create_trigger(self._redraw, 0)
        self.bind(pos=self._view_changed, size=self._view_changed, follow=self._view_changed)

    # -- data ---------------------------------------------------------------------

    def set_track(self, east, north) -> None:
        """Replace the track (lists of metres, first point = start)."""
        self.east = list(east) or [0.0]
        self.north = list(north) or [0.0]
        self.position = (self.east[-1], self.north[-1])
        self._line_dirty = True
        self._trigger()

    def set_heading(self, heading_rad: float) -> None:
        self.heading_rad = heading_rad
        self._trigger()

    def fit(self, *_) -> None:
        """Show the whole track; turns follow off."""
        self.follow = False
        self.vp.set_rect(self.x, self.y, self.width, self.height)
        self.vp.fit(self.east, self.north, margin_px=dp(48))  # clear of the button bar and scale bar
        self._view_changed()

    def _view_changed(self, *_):
        self._line_dirty = True
        self._trigger()

    # -- drawing ----------------------------------------------------------------------

    def _redraw(self, *_):
        vp = self.vp
        vp.set_rect(self.x, self.y, self.width, self.height)
        self._bg.pos, self._bg.size = self.pos, self.size
        if self.follow:
            old = vp.center
            vp.follow(*self.position)
            if old != vp.center:
                self._line_dirty = True
        if self._line_dirty:
            self._line.width = self.line_width
            self._line.points = vp.points(self.east, self.north)
            self._draw_grid()
            self._line_dirty = False
        r = dp(6)
        sx, sy = vp.to_screen(self.east[0], self.north[0])
        self._start.pos, self._start.size = (sx - r, sy - r), (2 * r, 2 * r)
        px, py = vp.to_screen(*self.position)
        r = dp(5)
        self._dot.pos, self._dot.size = (px - r, py - r), (2 * r, 2 * r)
        h = self.heading_rad
        if h == h:
            c, s = math.cos(h), math.sin(h)
            tip, back, half = dp(22), dp(4), dp(7)
            bx, by = px - back * c, py - back * s
            self._arrow.points = [px + tip * c, py + tip * s, bx - half * s, by + half * c, bx + half * s,
                                  by - half * c]
        else:
            self._arrow.points = [px, py, px, py, px, py]
        self._draw_scale_bar()

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
        lbl.text = format_length(m)
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
            self._touches.pop(touch.uid, None)
            return True
        return super().on_touch_up(touch)
