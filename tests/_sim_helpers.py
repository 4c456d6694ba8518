"""Simulated walks changed after the fact (tests only)."""

from __future__ import annotations

import math

import numpy as np

from core.recording import Recording, Stream


def scale_acc_motion(rec: Recording, spans, scale: float) -> Recording:
    """``rec`` with the accelerometer's motion scaled by ``scale`` in each span: ``spans`` is a list of
    ``(mask over the acc samples, the reading the motion is taken about)``; the other streams are shared."""
    acc = rec.streams["acc"]
    v = acc.values.copy()
    for mask, rest in spans:
        v[mask] = rest + scale * (v[mask] - rest)
    streams = dict(rec.streams)
    streams["acc"] = Stream("acc", acc.t_ns, v, acc.columns, acc.unit, acc.note)
    return Recording(streams, dict(rec.device), dict(rec.metadata))


def upright_pendulum(swing_deg, stride_s=1.64, incline_deg=25.0, seconds=16.0, rate_hz=50.0, seed=0,
                     swing_beat_deg=0.0, swing_beat_s=8.0):
    """Grid samples (n, 6: acc, gyro) of a phone held upright in a hand that swings as a pendulum from the shoulder
    by ``+-swing_deg`` at the stride period, the phone inclined ``incline_deg`` in its screen plane (the screen
    faces the thigh: the swing turns it about its z axis), the body bouncing 1.5 m/s^2 at the step frequency.  The
    pendulum's length is the one that swings freely at the stride (``g / w^2``): its specific force stays along the
    arm, so the phone barely tilts and its norm (gravity plus the centripetal term) repeats every step, as at the
    ear; only the rotation tells the hand (issue #25: the TUNING Tyrex walks Jakob_Nexus5_*_Swinging).  ``swing_deg``
    3: the head's few degrees of a phone at the ear.  ``swing_beat_deg``: the swing's amplitude varies by
    ``+-swing_beat_deg`` about ``swing_deg`` over ``swing_beat_s`` (a real hand swings harder on some strides than on
    others, issue #25 h15/swingsteps).  Returns ``(t_s (n,), rows (n, 6))``."""
    rng = np.random.default_rng(seed)
    g = 9.81
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    w = 2.0 * math.pi / stride_s
    a = math.radians(swing_deg) + math.radians(swing_beat_deg) * np.sin(2.0 * math.pi * t / swing_beat_s)
    phi, dphi, ddphi = a * np.sin(w * t), a * w * np.cos(w * t), -a * w * w * np.sin(w * t)
    arm = g / w ** 2
    bounce = 1.5 * np.cos(2.0 * w * t)
    along = g * np.cos(phi) + arm * dphi ** 2 + bounce * np.cos(phi)  # towards the shoulder (the phone's top)
    tang = g * np.sin(phi) + arm * ddphi + bounce * np.sin(phi)
    psi = math.radians(incline_deg)
    noise = 0.3 * rng.standard_normal((len(t), 3))
    acc = np.stack([along * math.sin(psi) + tang * math.cos(psi), along * math.cos(psi) - tang * math.sin(psi),
                    np.zeros_like(t)], axis=1) + noise
    gyro = np.stack([np.zeros_like(t), np.zeros_like(t), dphi], axis=1) + 0.05 * rng.standard_normal((len(t), 3))
    return t, np.hstack([acc, gyro])


def upright_pendulum_recording(swing_deg: float, **kw) -> Recording:
    """:func:`upright_pendulum` as a recording (accelerometer and gyroscope streams at its rate, from t = 1000 s)."""
    t, rows = upright_pendulum(swing_deg, **kw)
    t_ns = (1_000_000_000_000 + np.round(t * 1e9)).astype(np.int64)
    streams = {"acc": Stream("acc", t_ns, rows[:, :3].copy(), ("x", "y", "z"), "m/s^2"),
               "gyro": Stream("gyro", t_ns.copy(), rows[:, 3:].copy(), ("x", "y", "z"), "rad/s")}
    return Recording(streams, {"model": "synthetic pendulum"}, {})
