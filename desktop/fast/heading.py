"""The rotation-matrix smoother over the grid arrays: a second implementation of
:class:`core.pdr.heading.RotationSmoother` (Tian et al. 2014, section 4.3).

The six elements of the first two rows of ``R(q)`` go through the
second-order Butterworth low-pass (the ``lfilter`` recursion, direct form II
transposed, started at the first sample's steady state), and the walking
direction is the horizontal projection of the forward axis, switched to the
back of the phone while it stands upright (``forward_b="auto"``).  A compiled
loop in the reference's order of operations.  Deliberately a second
implementation (issue #13 item 3).
"""

from __future__ import annotations

import math

import numpy as np

from core.dsp import butter2_lowpass
from desktop.fast.jit import kernel


@kernel
def smooth(q, c, auto_axis, fwd0, up_enter, up_exit, out_east, out_north, out_heading, out_upright, counters):
    """Filter ``R(q)`` row by row of ``q`` (n, 4); the forward vector's East, North and heading per row.

    ``up_exit``: the exit threshold of the upright state per row (the reference's ``upright_exit`` at that grid
    sample: ``Pipeline(limb_upright_exit)`` changes it with the carry mode).  ``out_upright``: whether the back of
    the phone was the forward axis at each row; ``counters`` (in/out): [upright, axis switches, samples upright].
    """
    b0, b1, b2, a1, a2 = c[0], c[1], c[2], c[3], c[4]
    z1 = np.empty(6)
    z2 = np.empty(6)
    e = np.empty(6)
    yv = np.empty(6)
    upright = counters[0] != 0
    fx, fy, fz = fwd0[0], fwd0[1], fwd0[2]
    if upright:
        fx, fy, fz = 0.0, 0.0, -1.0
    for k in range(q.shape[0]):
        w, x, y, z = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
        e[0], e[1], e[2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        e[3], e[4], e[5] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        if k == 0:
            gain = (b0 + b1 + b2) / (1.0 + a1 + a2)
            for i in range(6):
                y0 = gain * e[i]
                z1[i] = y0 - b0 * e[i]
                z2[i] = b2 * e[i] - a2 * y0
        for i in range(6):
            yi = b0 * e[i] + z1[i]
            z1[i] = b1 * e[i] - a1 * yi + z2[i]
            z2[i] = b2 * e[i] - a2 * yi
            yv[i] = yi
        if auto_axis:
            y_norm = math.hypot(yv[1], yv[4])
            if not upright and y_norm < up_enter:
                upright = True
                fx, fy, fz = 0.0, 0.0, -1.0
                counters[1] += 1
            elif upright and y_norm > up_exit[k]:
                upright = False
                fx, fy, fz = 0.0, 1.0, 0.0
                counters[1] += 1
            if upright:
                counters[2] += 1
        east = yv[0] * fx + yv[1] * fy + yv[2] * fz
        north = yv[3] * fx + yv[4] * fy + yv[5] * fz
        out_east[k] = east
        out_north[k] = north
        out_heading[k] = math.atan2(north, east)
        out_upright[k] = upright
    counters[0] = 1 if upright else 0


def smooth_headings(smoother, q: np.ndarray, up_exit=None):
    """(east, north, heading, upright) of the reference ``smoother``'s settings over the attitudes ``q``
    (n, 4), and its counters (upright at the end, axis switches, samples upright).  ``up_exit``: the exit
    threshold per row (n,), default the smoother's ``upright_exit`` everywhere."""
    b, a = butter2_lowpass(smoother.cutoff_hz, smoother.grid_rate_hz)
    c = np.array([b[0] / a[0], b[1] / a[0], b[2] / a[0], a[1] / a[0], a[2] / a[0]])
    n = len(q)
    east, north, heading = np.empty(n), np.empty(n), np.empty(n)
    upright = np.zeros(n, dtype=np.bool_)
    counters = np.zeros(3, dtype=np.int64)
    fwd0 = np.array((0.0, 1.0, 0.0) if smoother.auto_axis else smoother.forward_b, dtype=np.float64)
    up_exit = np.full(n, smoother.upright_exit) if up_exit is None else np.ascontiguousarray(up_exit, dtype=np.float64)
    smooth(np.ascontiguousarray(q), c, smoother.auto_axis, fwd0, smoother.upright_enter, up_exit,
           east, north, heading, upright, counters)
    return east, north, heading, upright, counters
