"""The cascaded filters on the simulator: a drifting yaw gyro is held by the waist heading (TCKF), not by ZUPT."""

import math

import numpy as np

from core.foot.course import CourseErrorFilter, CourseVerdict
from core.foot.ins import InsSettings
from core.foot.navigator import FootNavigator, FootSettings
from desktop.foot_simulator import footprints, simulate_foot


def _walk(seed=0):
    legs = [(28.0, 0.0), (14.0, math.pi / 2), (28.0, math.pi / 2), (14.0, math.pi / 2)]
    return simulate_foot(footprints(legs), rate_hz=100.0, acc_noise_m_s2=0.05, gyro_noise_rad_s=0.01,
                         gyro_bias_rad_s=(0.0, 0.0, 0.004), toe_out_rad=math.radians(10.0), waist=True,
                         waist_mag_noise_uT=1.0, foot_mag_disturbance_uT=15.0, seed=seed)


def _final_error(w, aid, zero_rate_update=False):
    # the zero-rate updates (on by default) learn this constant bias in the simulator's perfectly still
    # stances; off here, the drift is what ZUPT alone cannot see and the heading aids must hold
    fs = FootSettings(aid=aid, ins=InsSettings(zero_rate_update=zero_rate_update), hdr_gate_rad=0.0)  # no HDR
    res = FootNavigator(fs, waist_device="waist").run(w.recording, stance=w.stance)
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
    e_zaru, _ = _final_error(w, "zupt", zero_rate_update=True)
    assert e_zaru < 0.2 * e_zupt, (e_zaru, e_zupt)  # the default's zero-rate updates: 0.23 m
    used = [u for u in res.course_updates if u.used]
    assert len(used) > 20
    # eq. 25: the heading measurement's variance is the first filter's
    assert all(u.p_rad2 <= math.radians(10.0) ** 2 * (1 + 1e-12) for u in used)


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
    assert u.verdict is CourseVerdict.BORESIGHT and u.reason == "boresight"  # the enum decides, its text is shown
    assert math.isclose(f.offset_rad, 0.3)
    f.update(1 * ns, 0.3, 1.0, 0.0)  # z = 0 exactly
    x0, p0 = f.x, f.p
    f.predict(11 * ns)  # eq. 15 over 10 s
    assert math.isclose(f.p, math.exp(-0.2) * p0 + 0.01 ** 2 * 10.0, rel_tol=1e-9)
    # a stride whose course is 0.05 rad left of the waist heading minus offset: z = +0.05 (eq. 18)
    u = f.update(12 * ns, 0.35, 1.0, 0.0)
    assert u.used and math.isclose(u.z_rad, 0.05, abs_tol=1e-12)
    assert 0.0 < f.x < 0.05
    assert u.handover  # handover_strides = 1: every used stride is handed over once ...
    f.restart()  # ... and the filter starts again without information
    assert f.fresh and f.p == math.inf
    u = f.update(12 * ns + 1, 0.37, 1.0, 0.0, prior_var_rad2=0.01)
    assert u.used and math.isclose(f.x, 0.07, abs_tol=1e-12) and math.isclose(f.p, 0.1 ** 2)  # eq. 16, no prior
    assert math.isclose(u.nis, 0.07 ** 2 / (0.01 + 0.1 ** 2))  # gated on the second filter's variance
    # a turning stride gives no measurement
    assert f.update(13 * ns, 0.35 + 1.0, 0.0, 1.0).reason == "turning"


def test_tckf_heading_nees_within_its_chi_square_band():
    """Heading consistency (issue #27): 6 seeded walks whose errors are drawn from the filter's own model
    (noise densities, gyroscope bias from its prior, initial heading error from its prior, waist heading
    noise below the assumed 1 deg): the mean NEES of the final heading error must lie in the 95 % band of
    chi-square(6) / 6, [0.21, 2.41].  Before: the estimate of the first filter handed over at every stride
    (each stride's information counted again at every later one) and no account of the boresight offset:
    reported sd 0.25 deg, errors 1-2 deg, mean NEES 17."""
    from core import quaternion as quat
    from core.foot.course import CourseSettings

    nees = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        rate = 100.0
        w = simulate_foot(footprints([(16.8, 0.0), (5.6, math.pi / 2), (16.8, math.pi / 2)]), rate_hz=rate,
                          acc_noise_m_s2=0.02 * math.sqrt(rate), gyro_noise_rad_s=0.002 * math.sqrt(rate),
                          gyro_bias_rad_s=tuple(rng.normal(0.0, 0.002, 3)), toe_out_rad=math.radians(10.0),
                          waist=True, waist_mag_noise_uT=1.0, seed=seed)
        nav = FootNavigator(FootSettings(aid="tckf", initial_heading_from_mag=False,
                                         initial_heading_rad=math.radians(10.0) - math.pi / 2
                                         + rng.normal(0.0, math.radians(1.0)),
                                         course=CourseSettings(mag_heading_sd_rad=math.radians(1.0)),
                                         rts_smoother=False),  # the forward filter's own heading and P
                            waist_device="waist")
        res = nav.run(w.recording, stance=w.stance)
        assert sum(u.used for u in res.heading_updates) > 10
        dq = quat.multiply(tuple(w.q_wxyz[-1]), quat.conjugate(nav.ins.q))
        e = float(quat.to_rotation_vector_array(np.array(dq))[0][2])
        if nav.foot_axis_b[1] == 1.0:  # the heading was given for the body y axis: a quarter turn apart
            e = e - math.pi / 2 if e > 0 else e + math.pi / 2
        nees.append(e * e / nav.ins.P[2, 2])
    assert 0.21 < float(np.mean(nees)) < 2.41, nees
