"""The cascaded filters on the simulator: a drifting yaw gyro is held by the waist heading (TCKF), not by ZUPT."""

import math

import numpy as np

from core.foot.course import CourseErrorFilter
from core.foot.navigator import FootNavigator, FootSettings
from desktop.foot_simulator import footprints, simulate_foot


def _walk(seed=0):
    legs = [(28.0, 0.0), (14.0, math.pi / 2), (28.0, math.pi / 2), (14.0, math.pi / 2)]
    return simulate_foot(footprints(legs), rate_hz=100.0, acc_noise_m_s2=0.05, gyro_noise_rad_s=0.01,
                         gyro_bias_rad_s=(0.0, 0.0, 0.004), toe_out_rad=math.radians(10.0), waist=True,
                         waist_mag_noise_uT=1.0, foot_mag_disturbance_uT=15.0, seed=seed)


def _final_error(w, aid):
    res = FootNavigator(FootSettings(aid=aid), waist_device="waist").run(w.recording, stance=w.stance)
    sp = res.stride_positions()
    # the track's frame: magnetic north from the (disturbed) foot magnetometer at the start; compare the
    # loop closure (the walk returns to its start), which no frame choice changes
    return math.hypot(sp[-1, 0] - sp[0, 0], sp[-1, 1] - sp[0, 1]), res


def test_tckf_beats_zupt_only_with_a_drifting_yaw_gyro():
    w = _walk(1)
    e_zupt, _ = _final_error(w, "zupt")
    e_tckf, res = _final_error(w, "tckf")
    assert e_zupt > 2.0  # 0.004 rad/s over ~70 s: about 16 deg
    assert e_tckf < 0.5 * e_zupt, (e_tckf, e_zupt)
    used = [u for u in res.course_updates if u.used]
    assert len(used) > 20
    # eq. 25: the heading measurement's variance is the first filter's
    assert all(u.p_rad2 < math.radians(10.0) ** 2 for u in used)


def test_foot_magnetometer_near_a_disturbed_floor_is_worse_than_tckf():
    w = _walk(2)
    e_mag, _ = _final_error(w, "foot_mag")
    e_tckf, _ = _final_error(w, "tckf")
    assert e_tckf < e_mag


def test_course_error_filter_equations():
    f = CourseErrorFilter(tau_s=100.0, process_noise_rad_sqrt_s=0.01, boresight_strides=1, gamma=1.0,
                          mag_heading_sd_rad=0.1, initial_sd_rad=0.2)
    ns = 1_000_000_000
    # the first stride has no previous one to tell a turn: no measurement
    assert f.update(0, 0.3, 1.0, 0.0).reason == "turning"
    # boresight stride: waist 0.3 rad, course 0 -> offset 0.3
    u = f.update(0, 0.3, 1.0, 0.0)
    assert u.reason == "boresight" and math.isclose(f.offset_rad, 0.3)
    f.update(1 * ns, 0.3, 1.0, 0.0)  # z = 0 exactly
    x0, p0 = f.x, f.p
    f.predict(11 * ns)  # eq. 15 over 10 s
    assert math.isclose(f.p, math.exp(-0.2) * p0 + 0.01 ** 2 * 10.0, rel_tol=1e-9)
    # a stride whose course is 0.05 rad left of the waist heading minus offset: z = +0.05 (eq. 18)
    u = f.update(12 * ns, 0.35, 1.0, 0.0)
    assert u.used and math.isclose(u.z_rad, 0.05, abs_tol=1e-12)
    assert 0.0 < f.x < 0.05
    f.applied(f.x)
    assert abs(f.x) < 1e-12
    # a turning stride gives no measurement
    assert f.update(13 * ns, 0.35 + 1.0, 0.0, 1.0).reason == "turning"
