"""Quaternion helpers against scipy's Rotation (scalar-first passed explicitly)."""

import math

import numpy as np

from core import quaternion as quat


def _random_q(rng):
    return quat.normalize(tuple(rng.normal(size=4)))


def test_to_matrix_matches_scipy_and_round_trips():
    from scipy.spatial.transform import Rotation  # here, not at collection (every xdist worker collects)

    rng = np.random.default_rng(3)
    for _ in range(50):
        q = _random_q(rng)
        m = np.array(quat.to_matrix(q))
        ref = Rotation.from_quat(q, scalar_first=True).as_matrix()
        np.testing.assert_allclose(m, ref, atol=1e-12)
        q2 = quat.from_matrix(quat.to_matrix(q))
        assert min(np.abs(np.array(q2) - q).max(), np.abs(np.array(q2) + q).max()) < 1e-12


def test_multiply_composes_rotations():
    from scipy.spatial.transform import Rotation  # here, not at collection (every xdist worker collects)

    rng = np.random.default_rng(4)
    p, q = _random_q(rng), _random_q(rng)
    ref = (Rotation.from_quat(p, scalar_first=True) * Rotation.from_quat(q, scalar_first=True)).as_matrix()
    np.testing.assert_allclose(quat.to_matrix(quat.multiply(p, q)), ref, atol=1e-12)


def test_triad_recovers_attitude_from_gravity_and_field():
    rng = np.random.default_rng(5)
    h_n = np.array([0.0, 20.0, -44.0])
    for _ in range(20):
        q = _random_q(rng)
        R = np.array(quat.to_matrix(q))
        acc_b = R.T @ np.array([0, 0, 9.81])
        mag_b = R.T @ h_n
        q_est = quat.from_two_vectors_enu(acc_b, mag_b)
        np.testing.assert_allclose(np.array(quat.to_matrix(q_est)), R, atol=1e-9)


def test_from_gravity_yaw_points_device_y_at_the_requested_heading():
    acc_b = (0.0, 9.81 * math.sin(0.4), 9.81 * math.cos(0.4))  # pitched up by 0.4 rad
    q = quat.from_gravity_yaw(acc_b, yaw_rad=1.0)
    R = np.array(quat.to_matrix(q))
    y_n = R[:, 1]
    assert math.atan2(y_n[1], y_n[0]) == __import__("pytest").approx(1.0, abs=1e-9)
    np.testing.assert_allclose(R @ np.array(acc_b) / 9.81, [0, 0, 1], atol=1e-9)
