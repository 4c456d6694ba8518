"""Unit quaternions ``q = (w, x, y, z)`` rotating body vectors into the navigation frame.

Plain-float functions (tuples in, tuples out) for the per-sample path, where
they are faster than numpy for 4-vectors, and their vectorised twins
(``*_array``: numpy arrays ``(..., 4)``) for whole recordings.  This is the
project's one quaternion module.  ``v_n = R(q) v_b`` with ``R`` from
:func:`to_matrix`; the paper's ``T_n^b`` (Tian et al. 2014, eq. 8) is ``R.T``.
"""

from __future__ import annotations

import math

import numpy as np


def multiply(p, q):
    """Hamilton product ``p (x) q``."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def conjugate(q):
    return (q[0], -q[1], -q[2], -q[3])


def normalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n == 0.0:
        raise ValueError("cannot normalise a zero quaternion")
    s = 1.0 / n
    return (q[0] * s, q[1] * s, q[2] * s, q[3] * s)


def to_matrix(q):
    """Rotation matrix (3 row tuples) of a unit quaternion: ``v_n = R v_b``."""
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def from_matrix(m):
    """Unit quaternion (w >= 0) of a rotation matrix given as 3 rows (Shepperd's method)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    tr = m00 + m11 + m22
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    q = normalize(q)
    return q if q[0] >= 0 else (-q[0], -q[1], -q[2], -q[3])


def rotate(q, v):
    """``R(q) v`` for a 3-vector ``v`` (body to navigation)."""
    m = to_matrix(q)
    return tuple(m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2] for i in range(3))


def from_axis_angle(axis, angle_rad):
    ax, ay, az = axis
    n = math.sqrt(ax * ax + ay * ay + az * az)
    s = math.sin(0.5 * angle_rad) / n
    return (math.cos(0.5 * angle_rad), ax * s, ay * s, az * s)


def from_rotation_vector(v):
    """Unit quaternion of the rotation vector ``v`` (axis times angle, rad): ``exp(v / 2)``."""
    ax, ay, az = v
    theta = math.sqrt(ax * ax + ay * ay + az * az)
    if theta < 1e-12:
        return normalize((1.0, 0.5 * ax, 0.5 * ay, 0.5 * az))
    s = math.sin(0.5 * theta) / theta
    return (math.cos(0.5 * theta), ax * s, ay * s, az * s)


def from_two_vectors_enu(acc_b, mag_b):
    """Attitude (body -> ENU) from one accelerometer and one magnetometer vector (TRIAD).

    ``acc_b`` is the specific force (points up at rest); ``mag_b`` the
    magnetic field.  The rows of ``R`` are East, North and Up expressed in
    the body frame.  Raises ``ValueError`` when the vectors are (nearly)
    parallel.
    """
    up = _unit(acc_b)
    east = _unit(_cross(mag_b, up))
    north = _cross(up, east)
    return from_matrix((east, north, up))


def from_gravity_yaw(acc_b, yaw_rad=0.0):
    """Attitude from the accelerometer alone, with the device y axis' heading set to ``yaw_rad``.

    ``yaw_rad`` is the heading (counter-clockwise from East) of the
    horizontal projection of the device y axis.  Used when there is no
    magnetometer.
    """
    up = _unit(acc_b)
    y_b = (0.0, 1.0, 0.0)
    d = sum(a * b for a, b in zip(y_b, up))
    fwd = _unit(tuple(y - d * u for y, u in zip(y_b, up)))  # horizontal forward in body coords
    left = _cross(up, fwd)
    # forward = cos(yaw) E + sin(yaw) N ; left = -sin(yaw) E + cos(yaw) N
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    east = tuple(c * f - s * l for f, l in zip(fwd, left))
    north = tuple(s * f + c * l for f, l in zip(fwd, left))
    return from_matrix((east, north, up))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n < 1e-9:
        raise ValueError("vector too short to normalise")
    return (v[0] / n, v[1] / n, v[2] / n)


# ---------------------------------------------------------------------------
# vectorised: arrays (..., 4) of quaternions (w, x, y, z), broadcasting


def multiply_array(p, q) -> np.ndarray:
    """Hamilton product of (..., 4) arrays (broadcasting)."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def to_matrix_array(q) -> np.ndarray:
    """(..., 3, 3) rotation matrices of (..., 4) unit quaternions (``v_n = R v_b``)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def about_axis_array(axis: int, angle_rad) -> np.ndarray:
    """Quaternions (..., 4) of rotations by ``angle_rad`` (...) about the x (0), y (1) or z (2) axis."""
    a = np.asarray(angle_rad, dtype=np.float64) * 0.5
    q = np.zeros(a.shape + (4,))
    q[..., 0] = np.cos(a)
    q[..., 1 + axis] = np.sin(a)
    return q


def canonical_sign_array(q) -> np.ndarray:
    """The same rotations with ``w >= 0`` (q and -q are one rotation)."""
    q = np.array(q, dtype=np.float64)
    flip = q[..., 0] < 0
    q[flip] = -q[flip]
    return q


def to_rotation_vector_array(q) -> np.ndarray:
    """Rotation vectors (n, 3) (axis * angle, angle in [0, pi]) of unit quaternions (n, 4)."""
    q = canonical_sign_array(np.atleast_2d(q))
    v = q[:, 1:]
    n = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(n, q[:, 0])
    small = n < 1e-9
    scale = np.where(small, 2.0 / np.maximum(q[:, 0], 0.5), angle / np.where(small, 1.0, n))
    return v * scale[:, None]
