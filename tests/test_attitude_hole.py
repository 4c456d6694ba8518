"""The attitude filter across a hole in the recording: every stream silent for seconds (issue #27, h13/gapatt).

A real RIDI walk (``ridi_huayi_bag2``) has a 4.4-s hole in all its streams.  Before the fix the filter closed its
open 0.1-s accelerometer and magnetometer intervals with the first reading after the hole: eleven readings of the
phone before the hole (rotated into the navigation frame with the attitude it had then) to one after, so the old
attitude was measured again as if new and the hole's honest uncertainty (``no_gyro_random_walk_rad_sqrt_s``) was
taken back at once; a phone that had turned far in the hole then had its first fresh magnetometer readings gated
until the relock.  And the uncertainty grew twice when the accelerometer's reading came before the gyroscope's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from core import quaternion as quat
from core.conventions import wrap_angle
from core.pdr.attitude import AttitudeEKF
from core.pdr.attitude_qekf import QuaternionEKF
from core.recording import Recording, Stream
from desktop.simulator import simulate_walk


def _holed(rec: Recording, a_ns: int, b_ns: int) -> Recording:
    """``rec`` without any event in ``[a_ns, b_ns)``."""
    streams = {}
    for name, s in rec.streams.items():
        keep = (s.t_ns < a_ns) | (s.t_ns >= b_ns)
        streams[name] = Stream(name, s.t_ns[keep], s.values[keep], s.columns, s.unit, s.note)
    return Recording(streams, dict(rec.device), dict(rec.metadata))


@pytest.mark.parametrize("seed", [1, 2])
def test_a_turn_inside_a_hole_is_taken_from_the_first_readings_after_it(seed):
    # 50 Hz, a 120-deg corner inside a 4.5-s hole in every stream: one second after the hole the heading is the
    # magnetometer's again (before the fix: -14.8 and -25.5 deg, seed 2 gated 160 readings until the relock;
    # after it -4.7 and -4.5, nothing gated)
    turn = math.radians(120.0)
    walk = simulate_walk([(0.0, 0.0), (14.0, 0.0), (14.0 + 25.0 * math.cos(turn), 25.0 * math.sin(turn))],
                         rate_hz=50.0, seed=seed, still_start_s=2.0, still_end_s=0.5)
    truth = walk.truth
    corner_ns = truth.walk_start_t_ns + int(14.0 / 1.26 * 1e9)
    a, b = corner_ns - 2_250_000_000, corner_ns + 2_250_000_000
    rec = _holed(walk.recording, a, b)
    ekf = AttitudeEKF()
    handlers = {"gyro": ekf.predict, "acc": ekf.update_acc, "mag": ekf.update_mag}
    err_deg = math.nan
    for name, t, v in rec.events(["gyro", "acc", "mag"]):
        handlers[name](t, *v)
        if t >= b + 1_000_000_000:
            R = quat.to_matrix(ekf.q)
            k = min(int(np.searchsorted(truth.att_t_ns, t)), len(truth.att_t_ns) - 1)
            err_deg = math.degrees(wrap_angle(math.atan2(R[1][1], R[0][1]) - truth.att_device_heading_rad[k]))
            break
    assert abs(err_deg) < 8.0, err_deg
    c = ekf.counters()
    assert c["holes"] == 1
    assert c["mag_reasons"].get("gate", 0) == 0 and c["heading_relocks"] == 0


def _still(ekf: AttitudeEKF | QuaternionEKF, t0_ns: int, n: int, dt_ns: int = 20_000_000) -> int:
    """``n`` events of each stream of a still, level phone facing north (gyroscope, accelerometer, magnetometer)."""
    t = t0_ns
    for _ in range(n):
        ekf.predict(t, 0.0, 0.0, 0.0)
        ekf.update_acc(t, 0.0, 0.0, 9.81)
        ekf.update_mag(t, 0.0, 20.0, -44.0)
        t += dt_ns
    return t


@pytest.mark.parametrize("acc_first", [False, True])
def test_a_hole_grows_the_uncertainty_once_over_its_length_and_forgets_the_open_intervals(acc_first):
    ekf = AttitudeEKF()
    t = _still(ekf, 0, 101)  # 2.02 s: the intervals are open at the hole (4 readings of 6)
    assert ekf.snapshot().acc_sum.n > 0 and ekf.snapshot().mag_sum.n > 0
    P0 = ekf.P
    t_last = t - 20_000_000
    t_after = t_last + 4_000_000_000  # a 4-s hole in every stream
    if acc_first:
        ekf.update_acc(t_after, 0.0, 0.0, 9.81)
        ekf.predict(t_after, 0.0, 0.0, 0.0)
    else:
        ekf.predict(t_after, 0.0, 0.0, 0.0)
        ekf.update_acc(t_after, 0.0, 0.0, 9.81)
    flags = ekf.update_mag(t_after, 0.0, 20.0, -44.0)
    grown = ekf.settings.no_gyro_random_walk_rad_sqrt_s ** 2 * 4.0
    P = ekf.P
    for i in range(3):  # tilt and heading: once over the hole's 4 s, whichever stream came first
        assert P[i, i] == pytest.approx(P0[i, i] + grown, rel=1e-9)
    st = ekf.snapshot()
    assert st.acc_sum.n == 1 and st.mag_sum.n == 1  # fresh intervals: no reading from before the hole is in them
    assert flags.outcome.value == "used" and math.isnan(flags.nis)  # pending in its interval, no update yet
    assert ekf.counters()["holes"] == 1


def test_a_magnetometer_alone_at_1_hz_after_the_other_streams_stop_still_updates():
    # review finding: every 1-s gap of a magnetometer read alone was a new hole that dropped its open interval,
    # so it never updated (10 readings: 10 holes, no update); gaps one after another are one hole
    e = AttitudeEKF()
    t = 0
    for _ in range(200):  # 4 s at 50 Hz, the phone flat and still
        e.predict(t, 0.0, 0.0, 0.0)
        e.update_acc(t, 0.0, 0.0, 9.81)
        e.update_mag(t, 0.0, 20.0, -44.0)
        t += 20_000_000
    outcomes = []
    for _ in range(10):  # the accelerometer and gyroscope stop, the magnetometer goes on at 1 Hz
        t += 1_000_000_000
        outcomes.append(e.update_mag(t, 0.0, 20.0, -44.0).outcome.value)
    assert e.counters()["holes"] == 1
    assert outcomes.count("used") >= 4, outcomes


# ---------------------------------------------------------------------------
# the paper's quaternion EKF (core.pdr.attitude_qekf, the ablation's peer): the same growth, once

def _qekf_growth_s(q_ekf: QuaternionEKF, P0: np.ndarray) -> np.ndarray:
    """``P - P0`` in seconds of the no-gyroscope random walk: ``(P - P0) / (sigma^2 / 4 Xi Xi^T)``, element-wise
    where that is not zero (the attitude did not change, so ``Xi(q)`` is the same)."""
    w, x, y, z = q_ekf.q
    xi = np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])
    per_s = q_ekf.no_gyro_random_walk_rad_sqrt_s ** 2 * 0.25 * (xi @ xi.T)
    big = np.abs(per_s) > 1e-6
    return (q_ekf.P - P0)[big] / per_s[big]


#: an accelerometer reading far from |g| (a jolt): rejected, so the covariance shows the growth alone
_JOLT = (0.0, 0.0, 30.0)


@pytest.mark.parametrize("acc_first", [False, True])
def test_the_quaternion_ekf_grows_once_over_a_hole_whichever_stream_comes_first(acc_first):
    # before the fix the accelerometer's event after a 4-s hole grew P over the hole (no gyroscope for 0.1 s) and
    # the gyroscope's event then grew it again over the same 4 s: 8 s of growth
    f = QuaternionEKF()
    t = _still(f, 0, 101)
    P0 = f.P.copy()
    t_after = t - 20_000_000 + 4_000_000_000
    if acc_first:
        f.update_acc(t_after, *_JOLT)
        f.predict(t_after, 0.0, 0.0, 0.0)
    else:
        f.predict(t_after, 0.0, 0.0, 0.0)
        f.update_acc(t_after, *_JOLT)
    assert f.acc_rejected
    np.testing.assert_allclose(_qekf_growth_s(f, P0), 4.0, rtol=1e-9)


def test_the_quaternion_ekf_grows_once_over_a_gyroscope_gap_while_the_accelerometer_runs_on():
    # the gyroscope silent for 2 s, the accelerometer on at 50 Hz: before the fix its events grew P over the gap
    # and the gyroscope's first event again over all of it (3.88 s); now once, but for the 0.1 s after the last
    # gyroscope reading, in which another stream's events do not grow it (as in AttitudeEKF): 1.9 s
    f = QuaternionEKF()
    t = _still(f, 0, 101)
    P0 = f.P.copy()
    t_gyro = t - 20_000_000
    for k in range(1, 100):
        f.update_acc(t_gyro + k * 20_000_000, *_JOLT)
    f.predict(t_gyro + 2_000_000_000, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(_qekf_growth_s(f, P0), 1.9, rtol=1e-9)
