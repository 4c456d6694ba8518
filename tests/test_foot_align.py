"""A foot walk that starts moving (no still period of ``align_min_s``) still aligns, from its first stances."""

import math

import numpy as np

from core.foot.navigator import FootNavigator, FootSettings
from core.foot.stance import StanceSettings
from desktop.foot_simulator import footprints, simulate_foot
from tests._foot_helpers import run_streaming


def _running_start(seed=0):
    """Short stances (0.25 s, as in running) from the first sample: no still period of 0.3 s anywhere."""
    return simulate_foot(footprints([(14.0, 0.0)]), rate_hz=200.0, stance_s=0.25, swing_s=0.45, first_still_s=0.0,
                         last_still_s=0.0, acc_noise_m_s2=0.02, gyro_noise_rad_s=0.002, seed=seed)


def test_walk_that_starts_moving_aligns_on_its_first_stances():
    w = _running_start()
    fs = FootSettings(stance=StanceSettings(detector="shoe", threshold=1e5, window_s=0.05),
                      initial_heading_rad=-math.pi / 2)
    res = FootNavigator(fs).run(w.recording)
    ok = np.isfinite(res.position_n[:, 0])
    # aligned at the second stance at the latest (the first short stance waits for a second to confirm)
    assert ok.mean() > 0.8, ok.mean()
    assert res.counters["aligned_on_short_stance"] == 1
    i0 = int(np.flatnonzero(ok)[0])
    assert (res.t_ns[i0] - w.t_ns[0]) * 1e-9 < 2 * (0.25 + 0.45) + 0.1
    # and it tracks: the distance walked after the alignment within 3 %
    truth = w.position_n[-1, :2] - w.position_n[i0, :2]
    est = res.position_n[-1, :2] - res.position_n[i0, :2]
    assert abs(np.linalg.norm(est) - np.linalg.norm(truth)) < 0.03 * np.linalg.norm(truth)


def test_streaming_aligns_the_same_way():
    w = _running_start(1)
    fs = FootSettings(stance=StanceSettings(detector="shoe", threshold=1e5, window_s=0.05))
    batch = FootNavigator(fs).run(w.recording)
    stream = run_streaming(fs, w.recording)
    ok = np.isfinite(batch.position_n[:, 0])
    assert ok.any() and np.array_equal(ok, np.isfinite(stream.position_n[:, 0]))
    assert np.allclose(stream.position_n[ok], batch.position_n[ok], atol=1e-9)


def test_a_still_start_still_aligns_on_the_still_period():
    """The usual case is unchanged: a 2 s still start aligns on it, not on a short stance."""
    w = simulate_foot(footprints([(5.6, 0.0)]), rate_hz=200.0, acc_noise_m_s2=0.02, gyro_noise_rad_s=0.002)
    res = FootNavigator(FootSettings(stance=StanceSettings(threshold=1e5, window_s=0.05))).run(w.recording)
    assert res.counters["aligned_on_short_stance"] == 0
    assert np.isfinite(res.position_n[5, 0])
