"""The accelerometer norm on the uniform grid, over whole arrays: a second implementation of
:class:`core.dsp.GridResampler` and of eq. 2 (Tian et al. 2014).

The norm (eq. 2) is vectorised; the resampler is a compiled loop (its box
mean, interpolation and restart after a gap depend on the previous events), in
the reference's order of operations so that every grid value is the same
float.  Deliberately a second implementation (issue #13 item 3).
"""

from __future__ import annotations

import numpy as np

from desktop.fast.jit import kernel


def acc_norm(acc_b: np.ndarray) -> np.ndarray:
    """|a| of each row (eq. 2), evaluated as the reference does: ``sqrt(x*x + y*y + z*z)``."""
    x, y, z = acc_b[:, 0], acc_b[:, 1], acc_b[:, 2]
    return np.sqrt(x * x + y * y + z * z)


@kernel
def resample(t_ns, x, period_ns, max_gap_ns, out_t, out_x, out_src, out_restart):
    """Grid points of the events ``(t_ns, x)``; returns how many.

    ``out_src[k]``: the event that completed grid point ``k`` (the pipeline takes it after that event);
    ``out_restart[k]``: the point started a new grid (first event, or after a gap).
    """
    k = 0
    have = False
    nxt = 0
    prev_t = 0
    prev_x = 0.0
    s = 0.0
    n = 0
    for i in range(len(t_ns)):
        ti = t_ns[i]
        xi = x[i]
        if not have or ti - prev_t > max_gap_ns:
            have = True
            out_t[k], out_x[k], out_src[k], out_restart[k] = ti, xi, i, True
            k += 1
            nxt = ti + period_ns
            prev_t, prev_x = ti, xi
            s, n = 0.0, 0
            continue
        if ti <= prev_t:  # not monotonic: ignored, as the reference does
            continue
        last = -1
        while ti >= nxt:
            if n >= 2 and nxt == ti:
                value = (s + xi) / (n + 1)
            elif n >= 2:
                value = s / n
            else:
                w = (nxt - prev_t) / (ti - prev_t)
                value = prev_x + w * (xi - prev_x)
            out_t[k], out_x[k], out_src[k], out_restart[k] = nxt, value, i, False
            last = nxt
            k += 1
            s, n = 0.0, 0
            nxt += period_ns
        if last != ti:
            s += xi
            n += 1
        prev_t, prev_x = ti, xi
    return k


def grid_of(t_ns: np.ndarray, norm: np.ndarray, rate_hz: float, max_gap_s: float = 0.5):
    """(t, value, source event, restart) arrays of the grid of the accelerometer norm."""
    period_ns = int(round(1e9 / rate_hz))
    cap = len(t_ns) + int((int(t_ns[-1]) - int(t_ns[0])) // period_ns) + 2 if len(t_ns) else 1
    out_t = np.empty(cap, dtype=np.int64)
    out_x = np.empty(cap)
    out_src = np.empty(cap, dtype=np.int64)
    out_restart = np.empty(cap, dtype=np.bool_)
    k = resample(t_ns, norm, period_ns, int(max_gap_s * 1e9), out_t, out_x, out_src, out_restart)
    return out_t[:k].copy(), out_x[:k].copy(), out_src[:k].copy(), out_restart[:k].copy()
