"""core.kalman, the error-state kernel shared by the attitude filter and the foot INS (issue #27, defect 2).

The reset Jacobian is checked by finite differences of the exact map (the SO(3)
exponential and logarithm), the update against the information form of the
same linear-Gaussian problem, and the non-finite policy by feeding it what
must be refused.
"""

import math

import numpy as np
import pytest

from core import kalman
from core import quaternion as quat


def _rotation(v) -> np.ndarray:
    return np.array(quat.to_matrix(quat.from_rotation_vector(tuple(float(x) for x in v))))


def _log(R) -> np.ndarray:
    return quat.to_rotation_vector_array(np.array(quat.from_matrix(R.tolist())))[0]


def _spd(rng, n, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T + n * np.eye(n))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_skew_is_the_cross_product(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(kalman.skew(a) @ b, np.cross(a, b), atol=1e-15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_inject_rotation_turns_the_attitude_in_the_navigation_frame(seed):
    rng = np.random.default_rng(seed)
    q = quat.normalize(tuple(rng.normal(size=4)))
    d = 0.3 * rng.normal(size=3)
    R_new = np.array(quat.to_matrix(kalman.inject_rotation(q, d)))
    np.testing.assert_allclose(R_new, _rotation(d) @ np.array(quat.to_matrix(q)), atol=1e-14)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("angle", [0.05, 0.4])
def test_reset_jacobian_matches_finite_differences_of_the_exact_reset(seed, angle):
    """``e+ = log(exp([d + e]x) exp(-[d]x))``: its derivative at ``e = 0`` is SO(3)'s left Jacobian of ``d``;
    ``G = I + [d/2]x`` is it to first order (the rest, ``[d]x^2 / 6``, is at most ``angle^2 / 6``)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=3)
    d = angle * u / np.linalg.norm(u)
    eps = 1e-6
    J = np.zeros((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = eps
        plus = _log(_rotation(d + e) @ _rotation(d).T)
        minus = _log(_rotation(d - e) @ _rotation(d).T)
        J[:, j] = (plus - minus) / (2 * eps)
    G = kalman.reset_jacobian(d, 9, slice(3, 6))
    np.testing.assert_array_equal(np.delete(np.delete(G, [3, 4, 5], 0), [3, 4, 5], 1), np.eye(6))
    assert np.linalg.norm(G[3:6, 3:6] - J, 2) <= angle ** 2 / 6 + 1e-6
    wrong = np.eye(3) - 0.5 * kalman.skew(d)  # the body-frame formula
    assert np.linalg.norm(wrong - J, 2) > 0.9 * angle


def test_reset_covariance_is_g_p_gt_and_symmetric():
    rng = np.random.default_rng(5)
    P = _spd(rng, 6, 1e-3)
    d = np.array([0.1, -0.2, 0.3])
    G = kalman.reset_jacobian(d, 6)
    out = kalman.reset_covariance(P, d)
    np.testing.assert_allclose(out, G @ P @ G.T, atol=1e-15)
    np.testing.assert_array_equal(out, out.T)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_update_is_the_information_form_posterior(seed):
    rng = np.random.default_rng(seed)
    n, m = 6, 2
    P, Rm = _spd(rng, n, 0.1), _spd(rng, m, 0.05)
    H, y = rng.normal(size=(m, n)), rng.normal(size=m)
    c = kalman.correct(P, y, H, Rm)
    assert c.used and c.verdict is kalman.Verdict.USED
    info = np.linalg.inv(np.linalg.inv(P) + H.T @ np.linalg.inv(Rm) @ H)
    np.testing.assert_allclose(c.P, info, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(c.dx, info @ H.T @ np.linalg.inv(Rm) @ y, rtol=1e-10, atol=1e-12)
    S = H @ P @ H.T + Rm
    assert c.nis == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-12)


def test_a_selecting_measurement_given_as_a_slice_equals_the_full_jacobian():
    rng = np.random.default_rng(7)
    P, Rm, y = _spd(rng, 9, 0.1), 0.01 * np.eye(3), rng.normal(size=3)
    H = np.zeros((3, 9))
    H[:, 3:6] = np.eye(3)
    a, b = kalman.correct(P, y, slice(3, 6), Rm), kalman.correct(P, y, H, Rm)
    np.testing.assert_allclose(a.dx, b.dx, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-10, atol=1e-12)
    assert a.nis == pytest.approx(b.nis, rel=1e-12)
    with pytest.raises(ValueError):
        kalman.correct(P, y, slice(3, 6), Rm, adjust_gain=lambda K: None)


def test_a_consider_update_leaves_the_considered_states_and_their_variance_alone():
    rng = np.random.default_rng(8)
    P, Rm, y = _spd(rng, 6, 0.1), np.array([[0.01]]), np.array([0.3])
    H = rng.normal(size=(1, 6))

    def consider(K):
        K[0:2, :] = 0.0

    c = kalman.correct(P, y, H, Rm, adjust_gain=consider)
    assert c.used
    np.testing.assert_array_equal(c.dx[0:2], 0.0)
    np.testing.assert_allclose(c.P[0:2, 0:2], P[0:2, 0:2], rtol=1e-12)


def test_the_gate_and_the_non_finite_policy_return_no_state():
    rng = np.random.default_rng(9)
    P, Rm = _spd(rng, 6, 0.1), 0.01 * np.eye(3)
    H = rng.normal(size=(3, 6))
    gated = kalman.correct(P, np.array([100.0, 0.0, 0.0]), H, Rm, gate=9.0)
    assert gated.verdict is kalman.Verdict.GATE and gated.nis > 9.0 and gated.dx is None and gated.P is None
    bad = kalman.correct(P, np.array([math.nan, 0.0, 0.0]), H, Rm)
    assert bad.verdict is kalman.Verdict.NUMERICAL and bad.dx is None and not bad.used
    singular = kalman.correct(np.zeros((6, 6)), np.ones(3), H, np.zeros((3, 3)))
    assert singular.verdict is kalman.Verdict.NUMERICAL and math.isnan(singular.nis)
    inf_p = P.copy()
    inf_p[5, 5] = math.inf
    assert kalman.correct(inf_p, np.ones(3), H, Rm).verdict is kalman.Verdict.NUMERICAL
