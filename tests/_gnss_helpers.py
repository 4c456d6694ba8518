"""Shared by the GPS fusion tests (Chen: test_gnss.py, Kubrak: test_kubrak.py)."""

from __future__ import annotations

import functools
import math


def truth_error(walk, fused_step) -> float:
    """Horizontal distance (m) of a fused step's latitude/longitude from the simulator's true phone position."""
    from core.geodesy import geodetic_to_enu

    e, n = geodetic_to_enu(fused_step.lat_deg, fused_step.lon_deg, walk.truth.origin_lat_lon)
    p = walk.truth.phone_position_at(fused_step.t_ns)
    return math.hypot(e - p[0], n - p[1])


def truth_errors(walk, located) -> list:
    """:func:`truth_error` of each of ``located`` (fused steps or fix records: ``t_ns``, ``lat_deg``, ``lon_deg``),
    the simulator's true positions from one vectorised call instead of one call each."""
    import numpy as np

    from core.geodesy import geodetic_to_enu

    located = list(located)
    if not located:
        return []
    o = walk.truth.origin_lat_lon
    p = walk.truth.phone_position_at(np.array([x.t_ns for x in located], dtype=np.int64))
    out = []
    for x, (pe, pn) in zip(located, p[:, :2].tolist()):
        e, n = geodetic_to_enu(x.lat_deg, x.lon_deg, o)
        out.append(math.hypot(e - pe, n - pn))
    return out


def num_jac(f, x, eps=1e-6):
    """Central finite-difference Jacobian of ``f`` at ``x`` (for checking the filters' analytic Jacobians)."""
    import numpy as np

    y0 = f(x)
    J = np.zeros((len(y0), len(x)))
    for i in range(len(x)):
        d = np.zeros(len(x))
        d[i] = eps
        J[:, i] = (f(x + d) - f(x - d)) / (2 * eps)
    return J


@functools.cache
def six_minute_walk():
    """``outdoor_walk(7, minutes=6)`` at 50 Hz (not its 100: the pipeline over it is the costliest fixture of both
    files), simulated once per process: test_gnss.py and test_kubrak.py both walk it and run in one xdist worker
    (tests/conftest.py's numba unit).  Shared: read it, never change it in place."""
    from desktop.simulator import outdoor_walk

    walk = outdoor_walk(7, minutes=6, rate_hz=50.0)
    for s in walk.recording.streams.values():  # shared: a test that writes into it fails here, not in the other file
        s.t_ns.flags.writeable = s.values.flags.writeable = False
    return walk
