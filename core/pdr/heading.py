"""Heading correction: Butterworth low-pass of the rotation matrix (Tian et al. 2014, section 4.3).

The hand swings the phone at the stride and step frequencies; the heading
taken straight from the EKF attitude swings with it.  Low-pass filtering the
heading *angle* breaks at the +-180 deg wrap (the paper's Fig. 5), so the
filter runs on the elements of the rotation matrix instead, and the walking
heading is read from the filtered matrix.

Only the first two rows of ``R`` (the East and North components of the
device axes) enter the heading, so only those six elements are filtered; the
result is exactly what filtering all nine and then reading the heading would
give.  The walking direction is the horizontal projection of the device axis
``forward_b`` (the y axis for a phone held in front of the chest)::

    f_n = R_filtered forward_b,   heading = atan2(f_n[North], f_n[East])

The filter is causal (second order, ``cutoff_hz``), so the smoothed heading
lags the truth by about its group delay ``sqrt(2) / (2 pi fc)`` (0.45 s at
0.5 Hz).

A step's heading
----------------
A step moves the walker from one heel strike to the next, so its heading is
the mean walking direction over the step interval ``[t_prev, t_step]``, not
the direction at the peak: :func:`interval_heading` is the direction of the
mean of the smoothed forward vectors ``f_n`` over the delay-compensated
interval ``[t_prev + delay, t_step + delay]`` (a vector mean: circular, and
a phone held nearly vertical, whose ``f_n`` is short, weighs less).  The
pipeline and the benchmark's peers both use it.  Reading the heading
``delay`` after the peak instead, as before, gives the heading at the end
of the step: on a turn that is late by half a step.
"""

from __future__ import annotations

import math

import numpy as np

from core.dsp import Biquad, butter2_group_delay_s, butter2_lowpass


def interval_heading(t_ns, east, north, t0_ns: int, t1_ns: int) -> float:
    """Direction (rad, CCW from East) of the mean forward vector over ``t0_ns <= t <= t1_ns``.

    ``t_ns`` (sorted), ``east``, ``north``: the smoothed forward vector on the
    grid (:attr:`RotationSmoother.forward_east`, ``forward_north``).  The
    sample nearest ``t1_ns`` stands in when the interval holds none; nan for
    empty input.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) == 0:
        return math.nan
    i0 = int(np.searchsorted(t, t0_ns, side="left"))
    i1 = int(np.searchsorted(t, t1_ns, side="right"))
    if i1 <= i0:
        k = min(max(i1 - 1, 0), len(t) - 1)
        i0, i1 = k, k + 1
    e = float(np.sum(np.asarray(east[i0:i1], dtype=float)))
    n = float(np.sum(np.asarray(north[i0:i1], dtype=float)))
    return math.atan2(n, e)


#: ``forward_b="auto"``'s two candidate axes, in the order of :attr:`RotationSmoother.axis_forward`: the top edge, the back
SMOOTHER_AXES = ((0.0, 1.0, 0.0), (0.0, 0.0, -1.0))


class RotationSmoother:
    """Second-order Butterworth low-pass on the rotation matrix, run on a uniform grid.

    Parameters
    ----------
    cutoff_hz : float
        Cut-off frequency (Hz).  The hand sway sits at the stride frequency
        (about 0.9 Hz) and above; 0.5 Hz leaves a third of it at 0.9 Hz.
    grid_rate_hz : float
        Rate at which :meth:`update` is called (Hz).
    forward_b : tuple of 3 floats or "auto"
        Device axis that points in the walking direction.  ``"auto"``: the y axis
        (the top edge: a phone held in front of the chest), but the back of the
        phone (``-z``) while the phone stands upright -- its top edge within
        about 27 degrees of the vertical (a trouser pocket, a hand hanging at the
        side), where y has no horizontal direction left.  The back's direction
        is off the walking direction by a constant that only GPS (the heading
        error model of :mod:`core.gnss.heading_model`, its offset ``A``) or the
        carry-mode work of issue #17 can tell; without either the heading is
        consistent but not the walking direction.
    upright_enter, upright_exit : float
        ``"auto"``: the horizontal length of the filtered y axis below which the
        phone counts as upright, and above which it counts as not upright again
        (hysteresis, so the axis does not flicker).  A phone hanging top down in a
        swinging hand leans its smoothed top edge 40-50 deg off the vertical (the
        forearm's flexion, the swing, the attitude's tilt error under the swing),
        past 0.65: the pipeline widens the exit to 0.85 while the phone is on a
        limb (``Pipeline(limb_upright_exit)``, issue #25 section 3).
    """

    def __init__(self, *, cutoff_hz: float = 0.5, grid_rate_hz: float = 50.0, forward_b=(0.0, 1.0, 0.0),
                 upright_enter: float = 0.45, upright_exit: float = 0.65):
        self.cutoff_hz = float(cutoff_hz)
        self.grid_rate_hz = float(grid_rate_hz)
        self.auto_axis = isinstance(forward_b, str)
        if self.auto_axis and forward_b != "auto":
            raise ValueError(f"forward_b must be 3 floats or 'auto', got {forward_b!r}")
        self.forward_b = (0.0, 1.0, 0.0) if self.auto_axis else tuple(float(v) for v in forward_b)
        self.upright_enter = float(upright_enter)
        self.upright_exit = float(upright_exit)
        self.reset()

    @property
    def axis_forward(self):
        """``forward_b="auto"``: the horizontal (East, North) parts of both candidate axes after the last update,
        in the order of :data:`SMOOTHER_AXES` (the top edge ``y``, the back ``-z``); None before one or with a fixed
        axis."""
        y = self._y
        return None if y is None else ((y[1], y[4]), (-y[2], -y[5]))

    @property
    def delay_s(self) -> float:
        """Low-frequency group delay of the smoother (s)."""
        return butter2_group_delay_s(self.cutoff_hz)

    def reset(self) -> None:
        b, a = butter2_lowpass(self.cutoff_hz, self.grid_rate_hz)
        self._filters = [Biquad(b, a) for _ in range(6)]
        self._started = False
        self.heading_rad = math.nan
        #: East and North components of the filtered forward vector (its horizontal projection)
        self.forward_east = math.nan
        self.forward_north = math.nan
        #: horizontal length of the filtered forward vector (near 0: phone vertical, heading unreliable)
        self.horizontal_norm = math.nan
        #: ``forward_b="auto"``: whether the back of the phone is the forward axis now, switches, grid samples so
        self.upright = False
        self.n_axis_switches = 0
        self.n_upright = 0
        self._y = None  # the filtered rows of the last update (``axis_forward``)
        if self.auto_axis:
            self.forward_b = SMOOTHER_AXES[0]

    def update(self, mat_nb) -> float:
        """Filter one rotation matrix (3 row tuples, body -> ENU); returns the smoothed heading (rad)."""
        r0, r1 = mat_nb[0], mat_nb[1]
        fs = self._filters
        if not self._started:
            for f, x in zip(fs, (r0[0], r0[1], r0[2], r1[0], r1[1], r1[2])):
                f.reset(x)
            self._started = True
        f0, f1, f2, f3, f4, f5 = fs  # written out: a comprehension over the six costs more than their steps
        y = (f0.step(r0[0]), f1.step(r0[1]), f2.step(r0[2]), f3.step(r1[0]), f4.step(r1[1]), f5.step(r1[2]))
        if self.auto_axis:
            y_norm = math.hypot(y[1], y[4])
            if not self.upright and y_norm < self.upright_enter:
                self.upright, self.forward_b = True, SMOOTHER_AXES[1]
                self.n_axis_switches += 1
            elif self.upright and y_norm > self.upright_exit:
                self.upright, self.forward_b = False, SMOOTHER_AXES[0]
                self.n_axis_switches += 1
            self.n_upright += self.upright
            self._y = y  # a reference only: ``axis_forward`` is built when asked (Pipeline(cross_axis_modes))
        fx, fy, fz = self.forward_b
        east = y[0] * fx + y[1] * fy + y[2] * fz
        north = y[3] * fx + y[4] * fy + y[5] * fz
        self.forward_east, self.forward_north = east, north
        self.horizontal_norm = math.hypot(east, north)
        self.heading_rad = math.atan2(north, east)
        return self.heading_rad

    def run(self, mats) -> list[float]:
        """Smoothed headings for a sequence of rotation matrices on the grid (same kernel as :meth:`update`)."""
        self.reset()
        return [self.update(m) for m in mats]
