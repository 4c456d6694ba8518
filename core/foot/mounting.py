"""Is an IMU on the foot?  One product, two modes: foot-mounted navigation or the hand-held chain.

A foot-mounted IMU, while its wearer walks, is still (flat on the ground)
for a part of every stride and swings with angular rates of several rad/s in
between; a phone in the hand, the pocket or on the belt never stops moving
while its carrier walks and turns at a rad/s or two.  The evidence is
gathered per *walking window* (``activity_window_s`` windows whose
acceleration norm varies by more than ``active_acc_sd_m_s2``: standing on a
table is neither mode's evidence), so that a short episode of something else
-- the figure-of-eight a walker waves a phone in to calibrate its compass, at
10 rad/s -- cannot outvote the walk:

``peak_rate_rad_s``
    the median over walking windows of the window's largest ``|w|``;
``stride_fraction``
    the fraction of walking windows that look like a foot's stride: a swing
    (``|w|`` above ``swing_rate_rad_s``) and a still phase of at least
    ``still_min_s`` (``|w|`` below ``still_rate_rad_s`` and ``| |a| - g |``
    below ``still_acc_m_s2`` throughout).

The evidence adds up in the log-odds::

    logit(p_foot) = ln(peak / peak_rate_rad_s) / peak_rate_width
                    + (stride_fraction - stride_fraction0) / stride_fraction_width

History: a first version used the 99th percentile of ``|w|`` and the fraction
of still samples over the whole recording; it was right on every foot
benchmark recording but called every IPIN 2023 hand-held walk foot-mounted
(their compass-calibration waving gives 7-12 rad/s peaks, and a hand-held
phone is "still" for 10-20 % of its samples).  The window features were then
chosen on the tuning splits (IPIN routes 01, 02, 21, 22; IPOL odd subjects,
feet and lower back; PyShoe odd trials).  There, stride fractions are 0-0.2
hand-held and on the lower back against 0.6-1 on walking feet; window peaks
0.8-3 rad/s against 4.3-22, except IPIN walks with long waving (up to 7.3).
Running feet (PyShoe's 2017-11-27 session) have fewer still phases (stride
fractions 0.25-0.6) and are still called foot-mounted, less surely.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.conventions import ACC, GYRO, STANDARD_GRAVITY_M_S2
from core.foot.devices import stream_name
from core.foot.navigator import gyro_at
from core.recording import Recording

FOOT = "foot"
HANDHELD = "handheld"


@dataclass(frozen=True)
class MountingSettings:
    """Thresholds of :func:`detect_mounting` (units in the names)."""

    #: window peak rate (median over walking windows) without evidence either way (rad/s), its scale (log rate)
    peak_rate_rad_s: float = 5.0
    peak_rate_width: float = 0.25
    #: stride fraction without evidence either way, and its scale
    stride_fraction: float = 0.3
    stride_fraction_width: float = 0.05
    #: a stride: a swing faster than this (rad/s) ...
    swing_rate_rad_s: float = 3.0
    #: ... and a still phase at least this long (s), with |w| below this (rad/s) and |a| off g below this (m/s^2)
    still_min_s: float = 0.08
    still_rate_rad_s: float = 0.5
    still_acc_m_s2: float = 1.5
    #: walking windows: length (s) and acceleration-norm sd above which the window counts (m/s^2)
    activity_window_s: float = 2.0
    active_acc_sd_m_s2: float = 1.0


@dataclass(frozen=True)
class Mounting:
    """The decision, its confidence and the evidence."""

    mode: str  #: "foot" or "handheld"
    confidence: float  #: probability of the mode given (0.5 .. 1)
    p_foot: float
    peak_rate_rad_s: float  #: median over walking windows of the window's largest |w|
    stride_fraction: float  #: walking windows with a swing and a still phase
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
    rate = np.linalg.norm(gyr, axis=1)
    # windows of activity_window_s: the window of every sample
    w = ((t - t[0]) // int(s.activity_window_s * 1e9)).astype(np.int64)
    n_win = int(w[-1]) + 1
    count = np.bincount(w, minlength=n_win)
    s1 = np.bincount(w, weights=norm, minlength=n_win)
    s2 = np.bincount(w, weights=norm * norm, minlength=n_win)
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.sqrt(np.maximum(s2 / count - (s1 / count) ** 2, 0.0))
    walking = (count >= 10) & (sd > s.active_acc_sd_m_s2)
    if not np.any(walking):
        return Mounting(HANDHELD, 0.5, 0.5, math.nan, math.nan, 0.0)
    walking_s = float(np.sum(walking)) * s.activity_window_s
    peak_w = np.full(n_win, -np.inf)
    np.maximum.at(peak_w, w, rate)
    peak = float(np.median(peak_w[walking]))
    # still runs, credited to the window they start in
    quiet = ~walking[w]
    g = float(np.median(norm[quiet])) if np.any(quiet) else STANDARD_GRAVITY_M_S2
    still = (rate < s.still_rate_rad_s) & (np.abs(norm - g) < s.still_acc_m_s2)
    edges = np.diff(np.concatenate(([0], still.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    long_run = (t[ends] - t[starts]) * 1e-9 >= s.still_min_s
    has_still = np.zeros(n_win, dtype=bool)
    has_still[w[starts[long_run]]] = True
    stride = walking & has_still & (peak_w > s.swing_rate_rad_s)
    frac = float(np.sum(stride) / np.sum(walking))
    p = _logistic((math.log(max(peak, 1e-6)) - math.log(s.peak_rate_rad_s)) / s.peak_rate_width
                  + (frac - s.stride_fraction) / s.stride_fraction_width)
    mode = FOOT if p >= 0.5 else HANDHELD
    return Mounting(mode, p if mode == FOOT else 1.0 - p, p, peak, frac, walking_s)
