"""The receiver's speed against the steps (core.gnss.pace, issue #26): a receiver that sees the walker cover half
the steps' distance is not following the walker (indoors), and the judge keeps its fixes out for a minute."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.gnss.judge import Cause, GpsJudge, GpsVerdict
from core.gnss.pace import PaceSettings, ReceiverPaceCheck
from tests.test_gnss_judge import ORIGIN, _gps, _walk


def _feed(check, speed_of_t, seconds=90.0, walk_m_s=1.4, stand=(None, None)):
    """1-Hz fixes of a walker going straight east at ``walk_m_s`` (standing in ``stand``); returns the states."""
    e, out = 0.0, []
    for t in np.arange(1.0, seconds, 1.0):
        if not (stand[0] is not None and stand[0] <= t < stand[1]):
            e += walk_m_s
        out.append(check.add_fix(int(t * 1e9), speed_of_t(t), (e, 0.0)))
    return out


def test_a_receiver_that_reports_the_walking_speed_is_never_slow():
    states = _feed(ReceiverPaceCheck(), lambda t: 1.4 * 0.8)  # the iOS walks' Doppler, 20 % low
    assert not any(s.slow_now for s in states)
    assert states[-1].ratio == pytest.approx(0.8, abs=1e-9)


def test_a_receiver_at_a_third_of_the_steps_speed_is_slow_once_its_window_holds_the_evidence_and_a_minute_after():
    s = PaceSettings()
    states = _feed(ReceiverPaceCheck(s), lambda t: 0.45 if t < 60.0 else 1.4, seconds=200.0)
    slow = [i + 1.0 for i, x in enumerate(states) if x.slow_now]  # fix times (s)
    assert slow[0] == pytest.approx(s.min_fixes + 1.0)  # min_fixes speeds with a step before each
    # slow windows go on until the window no longer holds enough slow speeds to pull the ratio under 0.5, then
    # the memory: nothing slow after that
    last_slow_window = max(i + 1.0 for i, x in enumerate(states) if x.ratio < s.min_ratio)
    assert slow[-1] == pytest.approx(last_slow_window + s.memory_s)
    assert len(slow) == int(slow[-1] - slow[0]) + 1


def test_no_speed_or_a_standing_walker_is_no_evidence():
    assert not any(x.slow_now for x in _feed(ReceiverPaceCheck(), lambda t: math.nan))
    # a receiver without a velocity solution reports 0.0 (an outdoor cold start): no evidence either
    assert not any(x.slow_now for x in _feed(ReceiverPaceCheck(), lambda t: 0.0))
    # standing for 60 s with the receiver at 0: the window's steps walked under min_walk_m
    states = _feed(ReceiverPaceCheck(), lambda t: 0.0 if 20.0 <= t < 80.0 else 1.4, seconds=120.0, stand=(18.0, 82.0))
    assert not any(x.slow_now for x in states)


def test_a_gap_in_the_fixes_is_no_evidence():
    """A 3-minute outage: the steps walked 250 m between two fixes at walking speed (a failing test before the
    pairs across a gap were dropped: the ratio read 0.01)."""
    c = ReceiverPaceCheck()
    e = 0.0
    for t in list(np.arange(1.0, 30.0, 1.0)) + list(np.arange(210.0, 260.0, 1.0)):
        e = 1.4 * t
        st = c.add_fix(int(t * 1e9), 1.4, (e, 0.0))
        assert not st.slow_now
    assert st.ratio == pytest.approx(1.0, abs=1e-9)


def test_the_judge_keeps_a_slow_receiver_out_and_says_why_and_the_fused_track_is_dead_reckoning():
    from core.gnss import make_fusion

    steps = _walk(lambda t: 0.3, seconds=80.0)
    gps = _gps(steps, lambda t, e, n: (e, n), 5.0)  # perfect positions, speed 1.4 m/s = the steps'
    gps.values[:, 4] = 0.5  # the receiver says the walker crawls: indoors
    fr = make_fusion("kubrak").run(steps, gps, 0)  # Kubrak's filter (the --gps auto filter until bb61bda)
    assert fr.counters["gps_judge"]["causes"].get(Cause.PACE.value, 0) >= 65
    assert fr.counters["fixes_accepted"] <= 1  # the anchor only
    lat0, lon0 = fr.origin_lat_lon
    for fs, s in zip(fr.steps, steps):  # dead reckoning from the anchor: the steps themselves
        assert fs.east_m - fr.steps[0].east_m == pytest.approx(s.east_m - steps[0].east_m, abs=0.05)
        assert fs.north_m - fr.steps[0].north_m == pytest.approx(s.north_m - steps[0].north_m, abs=0.05)
    j = GpsJudge()
    for k, s in enumerate(steps[1::2]):
        from core.geodesy import enu_to_geodetic

        lat, lon = enu_to_geodetic(s.east_m, s.north_m, ORIGIN)
        v = j.add_fix(s.t_ns, float(lat), float(lon), 5.0, (s.east_m, s.north_m), None, 1.4 if k < 30 else 0.5)
    assert v.verdict is GpsVerdict.UNUSABLE and Cause.PACE in v.causes and v.pace_ratio < 0.5


def test_the_pace_is_pending_until_a_window_holds_the_evidence_and_never_without_speeds():
    assert not PaceSettings().wait_for_evidence  # off by default (no help on the tuning split)
    c = ReceiverPaceCheck(PaceSettings(wait_for_evidence=True))
    pend = [(c.add_fix(int(t * 1e9), 1.4, (1.4 * t, 0.0)), c.pending)[1] for t in np.arange(1.0, 30.0, 1.0)]
    # 8 pairs of 1.4 m (>= 10 m walked) at the 9th fix: pending until then
    assert pend[:8] == [False] + [True] * 7 and not any(pend[8:])
    c = ReceiverPaceCheck(PaceSettings(wait_for_evidence=True))
    assert not any((c.add_fix(int(t * 1e9), math.nan, (1.4 * t, 0.0)), c.pending)[1] for t in np.arange(1.0, 30.0))
