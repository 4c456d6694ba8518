"""Is an IMU on the foot?  One product, two modes: foot-mounted navigation or the hand-held chain.

A foot-mounted IMU, while its wearer walks, is still (flat on the ground)
for a large part of every stride and swings with angular rates of several
rad/s in between; a phone in the hand, the pocket or on the belt never stops
moving while its carrier walks and turns at a rad/s or two.  Two features
say which, computed over the whole recording (vectorised):

``peak_rate_rad_s``
    the 99th percentile of ``|w|`` over the samples in walking windows;
``stance_fraction``
    within walking windows, the fraction of samples that are flat and still:
    angular-rate energy over ``window_s`` below ``still_rate_rad_s^2`` and
    ``| |a| - g |`` below ``still_acc_m_s2``.

Walking windows are the ``activity_window_s`` windows whose acceleration
norm varies by more than ``active_acc_sd_m_s2`` (standing still on a table
is neither mode's evidence).  The evidence adds up in the log-odds::

    logit(p_foot) = ln(peak / peak_rate_rad_s) / peak_rate_width
                    + (stance_fraction - stance_fraction0) / stance_fraction_width

The two centres were chosen on the foot benchmark's tuning split (IPOL odd
subjects: both feet and the lower back; PyShoe odd trials) by a grid search:
no error there and the largest margin.  Peak rates there: 4.2-17 rad/s on
feet, 0.8-4.3 rad/s on the lower back (a U-turn); stance fractions 0.05-0.45
against 0.01-0.18: neither feature alone separates, both together do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.conventions import ACC, GYRO, STANDARD_GRAVITY_M_S2
from core.foot.devices import stream_name
from core.foot.navigator import gyro_at
from core.foot.stance import StanceSettings, statistic
from core.recording import Recording

FOOT = "foot"
HANDHELD = "handheld"


@dataclass(frozen=True)
class MountingSettings:
    """Thresholds of :func:`detect_mounting` (units in the names)."""

    #: peak rate (99th percentile) without evidence either way (rad/s), and its scale (in log rate)
    peak_rate_rad_s: float = 5.0
    peak_rate_width: float = 0.25
    #: stance fraction without evidence either way, and its scale
    stance_fraction: float = 0.14
    stance_fraction_width: float = 0.05
    #: stillness of a sample: rate energy over the window below this squared (rad/s), |a| off g below this
    still_rate_rad_s: float = 0.3
    still_acc_m_s2: float = 1.0
    window_s: float = 0.1
    #: walking windows: length (s) and acceleration-norm sd above which the window counts (m/s^2)
    activity_window_s: float = 2.0
    active_acc_sd_m_s2: float = 1.0


@dataclass(frozen=True)
class Mounting:
    """The decision, its confidence and the evidence."""

    mode: str  #: "foot" or "handheld"
    confidence: float  #: probability of the mode given (0.5 .. 1)
    p_foot: float
    peak_rate_rad_s: float
    stance_fraction: float
    walking_s: float  #: time in walking windows (s); 0: no evidence (confidence 0.5)


def _logistic(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, x))))


def detect_mounting(recording: Recording, device: str = "", settings: MountingSettings | None = None) -> Mounting:
    """Whether the IMU of ``device`` ("" = primary) is foot-mounted, from its accelerometer and gyroscope."""
    s = settings or MountingSettings()
    acc_s = recording.stream(stream_name(ACC, device), "mounting detection")
    gyr_s = recording.stream(stream_name(GYRO, device), "mounting detection")
    t = acc_s.t_ns
    acc = acc_s.values
    gyr = gyro_at(gyr_s.t_ns, gyr_s.values, t)
    ok = np.all(np.isfinite(acc), axis=1) & np.all(np.isfinite(gyr), axis=1)
    t, acc, gyr = t[ok], acc[ok], gyr[ok]
    if len(t) < 10:
        return Mounting(HANDHELD, 0.5, 0.5, math.nan, math.nan, 0.0)
    norm = np.linalg.norm(acc, axis=1)
    # walking windows: the sd of |a| over activity_window_s (time-based, as the stance windows)
    win = StanceSettings(detector="amv", window_s=s.activity_window_s)
    act_sd = np.sqrt(statistic(win, t, np.column_stack([norm, np.zeros_like(norm), np.zeros_like(norm)]), gyr))
    active = act_sd > s.active_acc_sd_m_s2
    dt = np.diff(t) * 1e-9
    walking_s = float(np.sum(dt[active[1:]])) if len(dt) else 0.0
    if not np.any(active):
        return Mounting(HANDHELD, 0.5, 0.5, math.nan, math.nan, 0.0)
    rate = np.linalg.norm(gyr, axis=1)
    peak = float(np.quantile(rate[active], 0.99))
    energy = statistic(StanceSettings(detector="are", window_s=s.window_s), t, acc, gyr)
    g = float(np.median(norm[~active])) if np.any(~active) else STANDARD_GRAVITY_M_S2
    still = (energy < s.still_rate_rad_s ** 2) & (np.abs(norm - g) < s.still_acc_m_s2)
    frac = float(np.mean(still[active]))
    p = _logistic((math.log(max(peak, 1e-6)) - math.log(s.peak_rate_rad_s)) / s.peak_rate_width
                  + (frac - s.stance_fraction) / s.stance_fraction_width)
    mode = FOOT if p >= 0.5 else HANDHELD
    return Mounting(mode, p if mode == FOOT else 1.0 - p, p, peak, frac, walking_s)
