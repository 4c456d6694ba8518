"""The receiver's speed against the steps (core.gnss.pace, issue #26): a receiver that sees the walker cover half
the steps' distance is not following the walker (indoors), and the judge keeps its fixes out for a minute."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.gnss.judge import Cause, GpsJudge, GpsVerdict
from core.geodesy import enu_to_geodetic
from core.gnss.pace import PaceSettings, ReceiverPaceCheck
from test_gnss_judge import ORIGIN, _gps, _walk


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


def _slow_start_judged(settings, receiver_m_s, walker_m_s=0.4, seconds=40.0, gap=(None, None)):
    """A walker starting slowly (IPIN tuning loops: 6-8 m in their first 18 s) with 1-Hz fixes exactly on the path, the
    receiver reporting ``receiver_m_s`` (nan: no speed); fixes in ``gap`` left out.  The judgements."""
    org = (47.0, 8.0)
    j, out = GpsJudge(settings), []
    for t in np.arange(1.0, seconds, 1.0):
        if gap[0] is not None and gap[0] <= t < gap[1]:
            continue
        e = walker_m_s * t
        lat, lon = enu_to_geodetic(e, 0.0, org)
        out.append(j.add_fix(int(t * 1e9), float(lat), float(lon), 4.0, (e, 0.0), None, receiver_m_s))
    return out


def test_with_evidence_first_a_stream_is_not_usable_before_the_receiver_shows_it_follows_the_walker():
    """IPIN's early fixes: the pace window needs 10 m of walking; a slow starter's stale indoor fixes were usable
    after the 10-s settling, before it (IPIN tuning T02r02: six taken at 17-22 s, the pace said slow at 23 s)."""
    from core.gnss.judge import JudgeSettings

    assert not JudgeSettings().evidence_first  # off by default (it costs on the IPIN tuning split)
    plain = _slow_start_judged(JudgeSettings(), 0.1, seconds=60.0)
    assert any(v.verdict is GpsVerdict.USABLE for v in plain)  # what it guards against
    wait = _slow_start_judged(JudgeSettings(evidence_first=True), 0.1, seconds=60.0)
    assert not any(v.verdict is GpsVerdict.USABLE for v in wait)
    first_slow = next(k for k, v in enumerate(wait) if Cause.PACE in v.causes)
    assert all(Cause.NO_EVIDENCE in v.causes for v in wait[8:first_slow]) and first_slow > 8
    assert all(v.verdict is GpsVerdict.UNKNOWN for v in wait[:first_slow])  # no evidence either way yet
    # a receiver that keeps up: usable once the window holds the evidence and the stream has settled
    ok = _slow_start_judged(JudgeSettings(evidence_first=True), 0.4, seconds=60.0)
    k = next(k for k, v in enumerate(ok) if v.verdict is GpsVerdict.USABLE)
    assert ok[k].proven and not math.isnan(ok[k].pace_ratio) and not ok[k - 1].proven
    assert ok[k - 1].causes == (Cause.NO_EVIDENCE,)  # settled meanwhile: usable with the evidence, no new wait


def test_with_evidence_first_a_stream_proves_itself_again_after_a_long_gap_and_without_speeds_by_walking():
    from core.gnss.judge import JudgeSettings

    js = JudgeSettings(evidence_first=True)
    # no speeds: the steps walk 15 m (evidence_min_walk_m) within the window with the fixes consistent
    v = _slow_start_judged(js, math.nan, walker_m_s=1.4, seconds=40.0)
    k = next(k for k, x in enumerate(v) if x.proven)
    assert k == 11  # 15.4 m walked between the 1st and the 12th fix (1 s apart)
    # a gap of 70 s (> resume_max_gap_s): proven afresh; the window refills first
    v = _slow_start_judged(js, math.nan, walker_m_s=1.4, seconds=130.0, gap=(40.0, 110.0))
    assert v[38].proven and not v[39].proven and Cause.NO_EVIDENCE in v[39 + 8].causes
    assert v[-1].verdict is GpsVerdict.USABLE or v[-1].causes == (Cause.SETTLING,)
