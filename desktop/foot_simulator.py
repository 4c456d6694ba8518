"""A foot-motion simulator with exact truth, for testing :mod:`core.foot` (not built from its models).

The foot follows a parametric gait: a stance of ``stance_s`` with the foot
flat and still, then a swing of ``swing_s`` in which

* the position moves from one footprint to the next along the straight line
  between them with ``s(u) = u - sin(2 pi u) / (2 pi)`` (u = swing phase 0..1;
  zero velocity at both ends) and rises by ``lift_m (1 - cos(2 pi u)) / 2``;
* the foot pitches about its lateral axis by
  ``pitch_rad (sin(2 pi u) / 2 - sin(4 pi u) / 4)`` (toe down at push-off,
  toe up before the strike; zero angle and rate at both ends);
* the yaw turns from one footprint's to the next's with the same ``s(u)``.

Everything is differentiated analytically, so the IMU data are exact: the
body frame is the Android device frame of a phone strapped flat on the shoe,
screen up, top edge to the toes (x right, y forward, z up), with
``R = Rz(yaw) Rx(pitch)``; the angular rate is
``w_b = (pitch', yaw' sin(pitch), yaw' cos(pitch))`` and the specific force
``f_b = R^T (a_n + (0, 0, g))``.  The foot's yaw is the walking course plus a
toe-out angle.  Optional sensor errors (seeded): white noise, constant
biases, a foot magnetometer whose field is bent near the floor and a waist
magnetometer that sees the clean field with the waist facing the course.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2
from core.foot.devices import device_stream
from core.recording import Recording, make_stream


@dataclass
class FootWalk:
    """Exact truth of a simulated foot walk (every array per IMU sample)."""

    t_ns: np.ndarray
    position_n: np.ndarray  #: (n, 3) ENU (m)
    velocity_n: np.ndarray
    q_wxyz: np.ndarray  #: (n, 4) body -> ENU
    stance: np.ndarray  #: (n,) bool, the foot still
    acc_b: np.ndarray  #: exact specific force (no errors)
    gyro_b: np.ndarray
    footprints_n: np.ndarray  #: (m, 3) stance positions
    course_rad: np.ndarray  #: (m-1,) course of each stride
    recording: Recording | None = None
    info: dict = field(default_factory=dict)


def _rot(yaw, pitch):
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    n = len(yaw)
    m = np.zeros((n, 3, 3))
    # Rz(yaw) @ Rx(pitch)
    m[:, 0, 0] = cy
    m[:, 0, 1] = -sy * cp
    m[:, 0, 2] = sy * sp
    m[:, 1, 0] = sy
    m[:, 1, 1] = cy * cp
    m[:, 1, 2] = -cy * sp
    m[:, 2, 1] = sp
    m[:, 2, 2] = cp
    return m


def _quat(yaw, pitch):
    """(w, x, y, z) of Rz(yaw) Rx(pitch)."""
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    return np.column_stack([cy * cp, cy * sp, sy * sp, sy * cp])


def footprints(legs, stride_m: float = 1.4) -> np.ndarray:
    """Stance positions (m, 2) of a walk of straight ``legs`` [(length_m, turn_rad_before), ...] in strides.

    The first leg starts at the origin heading East turned by its turn angle.
    """
    pts = [np.zeros(2)]
    heading = 0.0
    for length, turn in legs:
        heading += turn
        n = max(1, int(round(length / stride_m)))
        step = length / n
        for _ in range(n):
            pts.append(pts[-1] + step * np.array([math.cos(heading), math.sin(heading)]))
    return np.array(pts)


def simulate_foot(prints_n, *, rate_hz: float = 200.0, stance_s: float = 0.6, swing_s: float = 0.5,
                  lift_m: float = 0.12, pitch_rad: float = 0.9, toe_out_rad: float = 0.0,
                  first_still_s: float = 2.0, last_still_s: float = 1.0, gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
                  acc_noise_m_s2: float = 0.0, gyro_noise_rad_s: float = 0.0, acc_bias_m_s2=(0.0, 0.0, 0.0),
                  gyro_bias_rad_s=(0.0, 0.0, 0.0), field_uT=(0.0, 20.0, -40.0), foot_mag_disturbance_uT: float = 0.0,
                  waist_mag_noise_uT: float = 0.0, waist: bool = False, seed: int = 0, t0_ns: int = 1_000_000_000,
                  jitter_s: float = 0.0) -> FootWalk:
    """Simulate one foot stepping through ``prints_n`` (m, 2); see the module docstring."""
    rng = np.random.default_rng(seed)
    prints = np.asarray(prints_n, dtype=float).reshape(-1, 2)
    m = len(prints)
    d = np.diff(prints, axis=0)
    course = np.arctan2(d[:, 1], d[:, 0]) if m > 1 else np.zeros(0)
    # the foot's yaw at each footprint: course of the stride that follows it (the last keeps the previous)
    c_at = np.concatenate([course, course[-1:]]) if m > 1 else np.zeros(1)
    yaw_fp = np.unwrap(c_at) + toe_out_rad - math.pi / 2  # body y axis along the course + toe-out
    period = stance_s + swing_s
    total = first_still_s + (m - 1) * period + last_still_s + stance_s
    dt = 1.0 / rate_hz
    t = np.arange(0.0, total, dt)
    if jitter_s > 0:
        t = t + rng.uniform(-jitter_s, jitter_s, len(t))
        t[0] = 0.0
        t = np.sort(t)
    n = len(t)
    pos = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    accn = np.zeros((n, 3))
    yaw = np.zeros(n)
    yawd = np.zeros(n)
    pitch = np.zeros(n)
    pitchd = np.zeros(n)
    stance = np.ones(n, dtype=bool)
    # stride k (0..m-2) swings from print k to k+1, starting at first_still_s + k * period + stance_s - stance_s
    k = np.floor((t - first_still_s) / period).astype(int)
    u_raw = (t - first_still_s - k * period - stance_s) / swing_s  # < 0 in the stance part
    swinging = (k >= 0) & (k < m - 1) & (u_raw > 0) & (u_raw < 1)
    ki = np.clip(k, 0, max(m - 2, 0))
    idx_fp = np.where(t < first_still_s, 0, np.clip(np.where(u_raw >= 1, k + 1, k), 0, m - 1))
    idx_fp = np.where(k >= m - 1, m - 1, idx_fp)
    pos[:, :2] = prints[idx_fp]
    yaw[:] = yaw_fp[idx_fp]
    u = np.where(swinging, u_raw, 0.0)
    w2 = 2 * math.pi
    s = u - np.sin(w2 * u) / w2
    sd = (1 - np.cos(w2 * u)) / swing_s  # ds/dt
    sdd = w2 * np.sin(w2 * u) / swing_s ** 2
    if m > 1:
        dd = d[ki]
        dyaw = (yaw_fp[ki + 1] - yaw_fp[ki])
        sw = swinging
        pos[sw, :2] = prints[ki[sw]] + s[sw, None] * dd[sw]
        vel[sw, :2] = sd[sw, None] * dd[sw]
        accn[sw, :2] = sdd[sw, None] * dd[sw]
        pos[sw, 2] = lift_m * (1 - np.cos(w2 * u[sw])) / 2
        vel[sw, 2] = lift_m * math.pi * np.sin(w2 * u[sw]) / swing_s
        accn[sw, 2] = lift_m * 2 * math.pi ** 2 * np.cos(w2 * u[sw]) / swing_s ** 2
        yaw[sw] = yaw_fp[ki[sw]] + s[sw] * dyaw[sw]
        yawd[sw] = sd[sw] * dyaw[sw]
        pitch[sw] = pitch_rad * (np.sin(w2 * u[sw]) / 2 - np.sin(2 * w2 * u[sw]) / 4)
        pitchd[sw] = pitch_rad * (math.pi * np.cos(w2 * u[sw]) - math.pi * np.cos(2 * w2 * u[sw])) / swing_s
        stance = ~sw
    R = _rot(yaw, pitch)
    f_n = accn + np.array([0.0, 0.0, gravity_m_s2])
    acc_b = np.einsum("nji,nj->ni", R, f_n)  # R^T f_n
    gyro_b = np.column_stack([pitchd, yawd * np.sin(pitch), yawd * np.cos(pitch)])
    t_ns = t0_ns + np.round(t * 1e9).astype(np.int64)
    acc_m = acc_b + np.asarray(acc_bias_m_s2) + rng.normal(0.0, acc_noise_m_s2, (n, 3)) * (acc_noise_m_s2 > 0)
    gyro_m = gyro_b + np.asarray(gyro_bias_rad_s) + rng.normal(0.0, gyro_noise_rad_s, (n, 3)) * (gyro_noise_rad_s > 0)
    h_n = np.asarray(field_uT, dtype=float)
    mag_n = np.tile(h_n, (n, 1))
    if foot_mag_disturbance_uT > 0:  # a field bent by the floor, varying along the walk
        phase = pos[:, 0] * 0.7 + pos[:, 1] * 0.4
        mag_n = mag_n + foot_mag_disturbance_uT * np.column_stack([np.sin(phase), np.cos(1.3 * phase), 0 * phase])
    mag_b = np.einsum("nji,nj->ni", R, mag_n)
    streams = {ACC: make_stream(ACC, t_ns, acc_m), GYRO: make_stream(GYRO, t_ns, gyro_m),
               MAG: make_stream(MAG, t_ns, mag_b)}
    if waist:
        # the waist faces the course of the current stride (the body turns with the walk), upright
        wyaw = np.unwrap(c_at)[np.clip(np.where(swinging, ki, idx_fp), 0, m - 1)] - math.pi / 2
        Rw = _rot(wyaw, np.zeros(n))
        w_acc = np.einsum("nji,nj->ni", Rw, np.tile([0.0, 0.0, gravity_m_s2], (n, 1)))
        w_mag = np.einsum("nji,nj->ni", Rw, np.tile(h_n, (n, 1)))
        w_mag = w_mag + rng.normal(0.0, waist_mag_noise_uT, (n, 3)) * (waist_mag_noise_uT > 0)
        streams["acc@waist"] = device_stream(ACC, "waist", t_ns, w_acc)
        streams["gyro@waist"] = device_stream(GYRO, "waist", t_ns, np.zeros((n, 3)))
        streams["mag@waist"] = device_stream(MAG, "waist", t_ns, w_mag)
    rec = Recording(streams, device={"model": "foot simulator", "placement": "foot"},
                    metadata={"simulator": "desktop.foot_simulator", "seed": seed}, source="foot simulator")
    fp = np.column_stack([prints, np.zeros(m)])
    return FootWalk(t_ns, pos, vel, _quat(yaw, pitch), stance, acc_b, gyro_b, fp, course, rec,
                    {"rate_hz": rate_hz, "stance_s": stance_s, "swing_s": swing_s, "toe_out_rad": toe_out_rad})
