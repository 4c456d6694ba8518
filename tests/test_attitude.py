"""The paper's adaptive quaternion EKF (core.pdr.attitude_qekf, kept for comparison): Jacobian, transition, physics.

Its "heading-only" option is not heading-only (it keeps the full Jacobian); the azimuth-disturbance test that
shows it is in tests/test_attitude_filter.py, beside the product filter's."""

import math

import numpy as np
import pytest

from core import quaternion as quat
from core.pdr.attitude_qekf import QuaternionEKF as AttitudeEKF, measurement_jacobian, predicted_measurement, transition_matrix


@pytest.mark.parametrize("v", [(0.0, 0.0, 1.0), (0.0, 0.41, -0.91), (0.3, 0.5, -0.81)])
def test_measurement_jacobian_matches_finite_differences(v):
    rng = np.random.default_rng(6)
    for _ in range(20):
        q = rng.normal(size=4)  # also off the unit sphere: the formula must hold everywhere
        H = measurement_jacobian(tuple(q), v)
        eps = 1e-6
        num = np.zeros((3, 4))
        for j in range(4):
            dq = np.zeros(4)
            dq[j] = eps
            num[:, j] = (np.array(predicted_measurement(tuple(q + dq), v)) -
                         np.array(predicted_measurement(tuple(q - dq), v))) / (2 * eps)
        np.testing.assert_allclose(H, num, atol=1e-7)


def test_paper_eq16_first_rows_agree_on_the_unit_sphere_only():
    """Eq. 16 row 3 uses |q| = 1 (4 q0, 0, 0, 4 q3): equal to ours in value on the sphere, not as a derivative."""
    q = quat.normalize((0.9, 0.1, -0.2, 0.3))
    w, x, y, z = q
    H = measurement_jacobian(q, (0.0, 0.0, 1.0))
    paper = np.array([[-2 * y, 2 * z, -2 * w, 2 * x], [2 * x, 2 * w, 2 * z, 2 * y], [4 * w, 0, 0, 4 * z]])
    np.testing.assert_allclose(H[:2], paper[:2], atol=1e-12)
    assert not np.allclose(H[2], paper[2])
    # both give the same change for a tangent (norm-preserving) perturbation
    t = np.array([0.1, 0.2, -0.3, 0.05])
    t -= (t @ np.array(q)) * np.array(q)
    assert H[2] @ t == pytest.approx(paper[2] @ t, abs=1e-12)


def test_transition_matrix_integrates_a_constant_rate_exactly():
    from scipy.spatial.transform import Rotation  # here, not at collection (every xdist worker collects)

    w = np.array([0.3, -1.2, 2.0])
    dt = 0.01
    F = transition_matrix(*w, dt)
    q0 = quat.normalize((0.8, 0.2, -0.1, 0.5))
    q = np.array(q0)
    for _ in range(100):
        q = F @ q
    ref = Rotation.from_quat(q0, scalar_first=True) * Rotation.from_rotvec(w * 1.0)
    np.testing.assert_allclose(Rotation.from_quat(q, scalar_first=True).as_matrix(), ref.as_matrix(), atol=1e-10)


def _still_phone_events(q_true, seconds=20.0, rate=100.0, seed=7, gyro_bias=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    R = np.array(quat.to_matrix(q_true))
    acc = R.T @ np.array([0.0, 0.0, 9.81])
    mag = R.T @ np.array([0.0, 20.0, -44.0])
    t = 10**12
    for k in range(int(seconds * rate)):
        t += int(1e9 / rate)
        yield "gyro", t, tuple(np.array(gyro_bias) + rng.normal(0, 0.003, 3))
        yield "acc", t + 1000, tuple(acc + rng.normal(0, 0.03, 3))
        if k % 2 == 0:
            yield "mag", t + 2000, tuple(mag + rng.normal(0, 0.4, 3))


def _run(ekf, events):
    for name, t, v in events:
        getattr(ekf, {"gyro": "predict", "acc": "update_acc", "mag": "update_mag"}[name])(t, *v)


def _angle_between(q1, q2):
    d = abs(sum(a * b for a, b in zip(q1, q2)))
    return 2 * math.acos(min(1.0, d))


@pytest.mark.parametrize("q_true", [(1.0, 0.0, 0.0, 0.0), quat.normalize((0.9, 0.3, -0.1, 0.4)),
                                    quat.normalize((0.2, 0.7, 0.6, -0.3))])
def test_still_phone_keeps_its_attitude(q_true):
    ekf = AttitudeEKF()
    _run(ekf, _still_phone_events(q_true, gyro_bias=(0.004, -0.003, 0.005)))
    assert ekf.initialized
    assert math.degrees(_angle_between(ekf.q, q_true)) < 1.0
    assert ekf.n_mag_rejected == 0


def test_wrong_start_converges_to_the_truth():
    q_true = quat.normalize((0.9, 0.1, 0.1, 0.4))
    ekf = AttitudeEKF()
    events = list(_still_phone_events(q_true, seconds=30))
    ekf.predict(events[0][1] - 10, 0, 0, 0)
    ekf.update_acc(events[0][1] - 5, 0.0, 0.0, 9.81)
    ekf.update_mag(events[0][1] - 4, 10.0, 10.0, -44.0)  # a wrong first attitude
    _run(ekf, events)
    assert math.degrees(_angle_between(ekf.q, q_true)) < 2.0


def test_magnetic_disturbance_is_rejected_and_flagged():
    q_true = (1.0, 0.0, 0.0, 0.0)
    ekf = AttitudeEKF()
    events = list(_still_phone_events(q_true, seconds=10))
    _run(ekf, events[: len(events) // 2])
    before = ekf.q
    # a steel door next to the phone: the field's norm drops by half
    disturbed = [(n, t, tuple(np.array(v) * 0.5 + (10.0, 0.0, 0.0)) if n == "mag" else v) for n, t, v in
                 events[len(events) // 2:]]
    _run(ekf, disturbed)
    assert ekf.mag_rejected and ekf.n_mag_rejected > 0
    assert math.degrees(_angle_between(ekf.q, before)) < 1.0


def _tilt_deg(q_est, q_true):
    """Angle between the estimated and the true 'up' in the body frame."""
    up_est = np.array(quat.to_matrix(q_est))[2]
    up_true = np.array(quat.to_matrix(q_true))[2]
    return math.degrees(math.acos(min(1.0, float(up_est @ up_true))))


