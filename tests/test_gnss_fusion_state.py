"""The GPS fusion stages' typed state (``FixFusionState`` with its groups, ``ChenFusionState``,
``KubrakFusionState``): ``reset()`` makes all of it afresh -- a used-then-reset fusion equals a new one value by
value, its filter, trainer and judge included -- and the public names of the state are read-only from outside."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.geodesy import enu_to_geodetic
from core.gnss.base import FixFusionState
from core.gnss.fusion import ChenFusionState, GpsFusion
from core.gnss.kubrak import KubrakFusion, KubrakFusionState
from core.pdr.pipeline import Step
from core.pdr.stride import StepFeatures
from tests._state_helpers import differences

ORIGIN = (47.37, 8.54)
T0 = 1_000_000_000_000


def _walk(seed: int = 3, n: int = 180):
    """``n`` half-second steps along a slow left bend (0.7 m, regressors of a normal walk) and a fix every second
    near the true position (2-4 m noise, a 25-m multipath jump from 40 to 48 s, a receiver status before each),
    in time order: ("step", Step) / ("status", t, values) / ("fix", t, values)."""
    rng = np.random.default_rng(seed)
    events, e, n_ = [], 0.0, 0.0
    for k in range(n):
        t = T0 + int((k + 1) * 0.5e9)
        h = 0.3 + 0.004 * k
        e, n_ = e + 0.7 * math.cos(h), n_ + 0.7 * math.sin(h)
        feats = StepFeatures(t, 0.5, 11.5, 8.5, 1.2, None, 9.9, 2.0, 1.1)
        step = Step(k, t, 0.7 * (1.0 + rng.normal(0, 0.02)), h + 0.15 + rng.normal(0, 0.03), e, n_, feats, True)
        events.append(("step", step))
        if k % 2 == 1:
            tf = t + int(0.2e9)
            off = 25.0 if 40e9 <= tf - T0 < 48e9 else 0.0
            lat, lon = enu_to_geodetic(e + off + rng.normal(0, 2.0), n_ + rng.normal(0, 2.0), ORIGIN)
            events.append(("status", tf, [9.0, 33.0]))
            events.append(("fix", tf, [float(lat), float(lon), 400.0, 3.0 + rng.uniform(0, 1), 1.4,
                                        math.degrees(math.pi / 2 - h)]))
    return events


def _feed(f, events) -> None:
    f.set_time_zero(T0)
    for ev in events:
        if ev[0] == "step":
            f.add_step(ev[1])
        elif ev[0] == "status":
            f.add_status(ev[1], ev[2])
        else:
            f.add_fix(ev[1], ev[2])
    f.finish()


@pytest.fixture(scope="module")
def events():
    return _walk()


CASES = [(GpsFusion, ChenFusionState, "_chen", {}),
         (KubrakFusion, KubrakFusionState, "_kub", {}),
         (GpsFusion, ChenFusionState, "_chen", {"hidden_ns": [(T0 + int(20e9), T0 + int(30e9))],
                                                "course_scatter_n": 6, "heading_lag_s": 5.0})]


@pytest.mark.parametrize("make, state_type, own, kw", CASES)
def test_reset_leaves_every_value_of_a_new_fusion(events, make, state_type, own, kw):
    used = make(**kw)
    _feed(used, events)
    c = used.counters()
    # the run went through the paths that change the state: fixes used, gated or judged out, a moved track
    assert c["fixes_accepted"] > 20 and c["fixes_gated"] + c["fixes_judged_out"] + c["fixes_relocked"] > 0
    assert used.gps_moves()["by_kind"] and used.origin_lat_lon is not None
    assert type(used._state) is FixFusionState and type(getattr(used, own)) is state_type
    fresh = make(**kw)
    assert differences(vars(used), vars(fresh)) != []  # the comparison sees a used fusion
    used.reset()
    assert differences(vars(used), vars(fresh)) == []


@pytest.mark.parametrize("make", [GpsFusion, KubrakFusion])
def test_the_state_is_read_only_from_outside(make):
    f = make()
    for name in ("origin_lat_lon", "anchor", "fixes", "steps", "outages", "relocks", "judge", "moves",
                 "fused_walked_m", "n_fixes_accepted", "n_fixes_hidden", "n_screened_out", "n_cn0", "n_judged_out",
                 "n_filter_rejected", "n_gated", "n_relocked", "last_step_ns"):
        with pytest.raises(AttributeError):
            setattr(f, name, getattr(f, name))
    if make is KubrakFusion:
        for name in ("shadow", "shadow_events", "unreliable_until_ns", "n_variability", "n_velocity_used",
                     "n_velocity_gated", "variability_events", "aligned"):
            with pytest.raises(AttributeError):
                setattr(f, name, getattr(f, name))
