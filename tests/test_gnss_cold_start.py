"""A receiver's cold start does not hold a stream hostage (issue #25 part 3, #26; ``JudgeSettings.cold_start_run``):
while a stream is still acquiring, the judge's accuracy test looks at the fixes since the reported accuracy last
dropped within its limit, where the receiver's pace (or the steps' walk) shows the stream follows the walker; an
indoor-like stream is still kept out."""

from __future__ import annotations

import math

import numpy as np

from core.geodesy import enu_to_geodetic
from core.gnss.judge import Cause, GpsJudge, GpsVerdict, JudgeSettings

ORIGIN = (47.0, 8.0)


def _judged(settings, hacc_of_t, speed_of_t, walker_m_s=1.4, seconds=60.0, seed=3):
    """A walker going straight east at ``walker_m_s``, 1-Hz fixes on the path (1 m per-axis noise: a cold start's
    converging fixes report far more than they are off, as on thomasdingemanse_lopen), reporting ``hacc_of_t(t)``
    and the receiver speed ``speed_of_t(t)``.  The times (s) and judgements."""
    rng = np.random.default_rng(seed)
    j, out = GpsJudge(settings), []
    for t in np.arange(1.0, seconds, 1.0):
        e = walker_m_s * t
        lat, lon = enu_to_geodetic(e + rng.normal(0.0, 1.0), rng.normal(0.0, 1.0), ORIGIN)
        out.append((float(t), j.add_fix(int(t * 1e9), float(lat), float(lon), float(hacc_of_t(t)), (e, 0.0), None,
                                        float(speed_of_t(t)))))
    return out


def _first_usable_s(judged):
    return next((t for t, jd in judged if jd.verdict is GpsVerdict.USABLE), math.inf)


def _cold_start(t):  # the reported accuracy falls from 25 m to 5 m over the first 20 s
    return max(5.0, 25.0 - t)


def test_a_cold_start_does_not_hold_back_the_good_fixes_after_it():
    s = JudgeSettings()
    assert s.cold_start_run  # on by default (thomasdingemanse_lopen's outages, tuning)
    judged = _judged(s, _cold_start, lambda t: 1.3)
    first_good = next(t for t, _ in judged if _cold_start(t) <= s.max_median_hacc_m)  # 15 s
    usable = _first_usable_s(judged)
    # taken once the good fixes have passed for the settling time, the cold start's coarse fixes in the window or not
    assert usable <= first_good + s.usable_after_s + 1.0
    assert all(jd.verdict is GpsVerdict.USABLE for t, jd in judged if t >= usable)
    # the rule before: the window's median waited for the coarse fixes to leave it, then settled afresh
    before = _first_usable_s(_judged(JudgeSettings(cold_start_run=False), _cold_start, lambda t: 1.3))
    assert before >= usable + 5.0


def test_a_coarse_fix_after_the_stream_was_usable_counts_again_in_the_window():
    """The cold-start rule is for acquiring: once usable, the window's median decides (a coarse fix then is the
    stream's); six coarse fixes in a row make the window's median coarse."""
    def hacc(t):
        return 20.0 if 40.0 <= t < 52.0 else _cold_start(t)

    judged = _judged(JudgeSettings(), hacc, lambda t: 1.3)
    causes = [jd.causes for t, jd in judged if 48.0 <= t < 52.0]
    assert all(Cause.ACCURACY in c for c in causes)


def test_an_indoor_like_stream_is_still_kept_out():
    """T22r03-like (IPIN tuning): 7 s reporting 12-16 m, then 8 m, while the receiver sees the walker cover a third of
    the steps' distance: the fine run alone is no evidence, and the pace check keeps the stream out."""
    def hacc(t):
        return 16.0 if t < 8.0 else 8.0

    judged = _judged(JudgeSettings(), hacc, lambda t: 1.4 / 3.0)
    assert _first_usable_s(judged) == math.inf
    assert any(Cause.PACE in jd.causes for _, jd in judged)


def test_without_evidence_that_the_stream_follows_the_walker_the_window_median_decides():
    """No receiver speed and a slow walker (6 m in 15 s, under ``evidence_min_walk_m``): the cold-start rule does not
    apply, the stream is judged as before (the window's median: usable at 31 s, not 24 s)."""
    def hacc(t):
        return 16.0 if t < 14.0 else 8.0

    on = _first_usable_s(_judged(JudgeSettings(), hacc, lambda t: math.nan, walker_m_s=0.4))
    off = _first_usable_s(_judged(JudgeSettings(cold_start_run=False), hacc, lambda t: math.nan, walker_m_s=0.4))
    assert on == off < math.inf
    walking = _first_usable_s(_judged(JudgeSettings(), hacc, lambda t: math.nan, walker_m_s=1.4))  # 21 m in 15 s
    assert walking <= on - 5.0


def test_the_fusion_takes_the_good_fixes_after_a_cold_start_and_not_the_coarse_ones():
    """Through the fusion (Chen's filter): the first fix taken comes one settling time after the reported accuracy
    dropped within the limit (15 s), not after the window's median had caught up (the rule before: 22 s and later),
    and no cold-start fix is taken."""
    from core.gnss import make_fusion
    from core.recording import Stream
    from test_gnss_judge import _walk

    steps = _walk(lambda t: 0.3, seconds=90.0)
    st = np.array([s.t_ns for s in steps])
    e, n = np.array([s.east_m for s in steps]), np.array([s.north_m for s in steps])
    rng = np.random.default_rng(5)
    rows, ts = [], []
    for t in np.arange(1.0, 85.0, 1.0):
        lat, lon = enu_to_geodetic(np.interp(t * 1e9, st, e) + rng.normal(0.0, 1.0),
                                   np.interp(t * 1e9, st, n) + rng.normal(0.0, 1.0), ORIGIN)
        rows.append((float(lat), float(lon), 400.0, _cold_start(t), 1.3, math.nan))
        ts.append(int(t * 1e9))
    gps = Stream("gps", np.array(ts, dtype=np.int64), np.array(rows),
                 ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg"),
                 ("deg", "deg", "m", "m", "m/s", "deg"), "")

    def first_taken(settings):
        fr = make_fusion("chen", judge=settings).run(steps, gps)
        taken = [f for f in fr.fixes if f.accepted]
        assert all(f.hacc_m <= 10.0 for f in taken[1:])  # the anchor aside, no cold-start fix
        return min((f.t_ns for f in taken[1:]), default=None) * 1e-9

    on, off = first_taken(JudgeSettings()), first_taken(JudgeSettings(cold_start_run=False))
    assert on <= 15.0 + JudgeSettings().usable_after_s + 1.0
    assert off >= on + 5.0
