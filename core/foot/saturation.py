"""Gyroscope readings clipped at the sensor's full scale, and their repair (issue #27).

A foot's swing turns faster than some IMUs measure: the PyShoe trials' MicroStrain 3DM-GX3-25 reads flat at
9.10-9.19 rad/s about its pitch axis for 5-15 samples (25-75 ms) of a hard stride, while the foot turns
faster.  The rotation missing from each such stride is an attitude error of several degrees that the next
stance's zero-velocity update can only partly explain (as tilt, and through its correlations as gyroscope
bias, the vertical one included); the rest is heading drift.

A run of readings of one axis at or beyond ``(1 - margin) x range`` is clipped.  Its values are replaced by a
parabola fitted by least squares (in time) to the ``flank`` unclipped readings on each side of the run, where
the parabola is beyond the reading (never below it: a clipped reading is a lower bound of the true rate).  A
run without ``flank`` unclipped readings of that axis on both sides is left as it was, and so is a run longer
than ``max_run_s`` (0.25 s: a swing's peak is shorter; a gyroscope at full scale for longer is stuck or spinning,
and no parabola over its flanks says what it missed).

Batch (:meth:`GyroClipRepair.repair`) and streaming (:meth:`GyroClipRepair.update` / :meth:`flush`) give the
same readings (tested): the stream holds the readings from the first clipped one until ``flank`` readings
unclipped on every axis follow, so a reading comes out up to the run's length plus ``flank`` samples late
(no delay while nothing is clipped); a run longer than ``max_run_s`` is released as it comes, so a stuck
gyroscope neither holds the live track nor grows the held list.

The range is a property of the sensor: a file or a live source declares it as Android's
``Sensor.getMaximumRange()`` of the gyroscope (rad/s, the sensor's unit), ``device["sensors"]["gyro"]["max_range"]``
(what the app writes in a recording's header); :func:`declared_gyro_range` reads it and refuses what cannot be one.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from core.conventions import GYRO

#: a declared full scale below this is refused (rad/s): the smallest full scale of MEMS gyroscopes is
#: +-125 deg/s = 2.18 rad/s, and a range too small would "repair" ordinary swings
MIN_GYRO_RANGE_RAD_S = 2.0


def declared_gyro_range(device) -> tuple[float, str]:
    """``(range_rad_s, problem)``: the gyroscope's full scale a device description declares
    (``device["sensors"]["gyro"]["max_range"]``, rad/s; module docstring).  Nothing declared: ``(nan, "")``.
    A value that cannot be a full scale (nan, inf, 0, negative, below :data:`MIN_GYRO_RANGE_RAD_S`, not a
    number: a broken sensor's report) is refused: ``(nan, why)``, and nothing is repaired."""
    sensors = device.get("sensors") if isinstance(device, dict) else None
    gyro = sensors.get(GYRO) if isinstance(sensors, dict) else None
    if not isinstance(gyro, dict) or gyro.get("max_range") is None:
        return math.nan, ""
    v = gyro["max_range"]
    r = float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan
    if math.isfinite(r) and r >= MIN_GYRO_RANGE_RAD_S:
        return r, ""
    return math.nan, f"the gyroscope reports a maximum range of {v!r} rad/s: not a full scale, ignored"


def clipped_runs(values, level: float) -> list[tuple[int, int, int]]:
    """``(axis, first, end)`` of every maximal run of ``|values[:, axis]| >= level`` (``end`` exclusive)."""
    w = np.asarray(values, dtype=float).reshape(len(values), -1)
    out = []
    for ax in range(w.shape[1]):
        m = np.abs(w[:, ax]) >= level
        d = np.diff(np.r_[0, m.astype(np.int8), 0])
        out += [(ax, int(i), int(j)) for i, j in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]
    return out


def repair_block(t_ns, values, level: float, flank: int, start: int = 0,
                 max_run_s: float = math.inf) -> tuple[np.ndarray, int]:
    """The readings with every clipped run that begins at or after ``start`` and lasts at most ``max_run_s``
    repaired (module docstring); ``(repaired copy, number of runs repaired)``."""
    t = np.asarray(t_ns, dtype=np.int64)
    w = np.array(values, dtype=float).reshape(len(t), -1)
    n = 0
    for ax, i, j in clipped_runs(w, level):
        if i < start or i < flank or j + flank > len(t) or (t[j - 1] - t[i]) * 1e-9 > max_run_s:
            continue
        idx = np.r_[i - flank:i, j:j + flank]
        if np.any(np.abs(w[idx, ax]) >= level):  # another run too close: no clean flank
            continue
        x = (t[idx] - t[i]) * 1e-9
        c = np.polyfit(x, w[idx, ax], 2)
        fit = np.polyval(c, (t[i:j] - t[i]) * 1e-9)
        sgn = 1.0 if w[i, ax] > 0 else -1.0
        w[i:j, ax] = sgn * np.maximum(sgn * fit, sgn * w[i:j, ax])
        n += 1
    return w, n


class GyroClipRepair:
    """Repairs clipped gyroscope readings (module docstring); ``range_rad_s`` nan: passes them through.

    ``repair(t_ns, values)`` for a whole stream; ``update(t_ns, values)`` -> the readings released (a list of
    ``(t_ns, values)``), ``flush()`` at the end.  ``n_repaired``: runs repaired so far.
    """

    def __init__(self, range_rad_s: float = math.nan, margin: float = 0.01, flank: int = 3,
                 max_run_s: float = 0.25):
        self.level = (1.0 - margin) * range_rad_s if math.isfinite(range_rad_s) and range_rad_s > 0 else math.nan
        self.flank = int(flank)
        self.max_run_s = float(max_run_s)
        self.reset()

    @property
    def active(self) -> bool:
        return math.isfinite(self.level)

    def reset(self) -> None:
        self.n_repaired = 0
        self._before: deque = deque(maxlen=self.flank)  # the last readings released (all unclipped)
        self._held: list = []  # readings from the first clipped one on
        self._run_start_ns: dict = {}  # axis -> the first reading of that axis's current clipped run

    def repair(self, t_ns, values) -> np.ndarray:
        """A whole stream at once (same result as :meth:`update` reading by reading, then :meth:`flush`)."""
        if not self.active:
            return np.asarray(values, dtype=float)
        w, n = repair_block(t_ns, values, self.level, self.flank, max_run_s=self.max_run_s)
        self.n_repaired += n
        return w

    def _clipped(self, v) -> bool:
        return any(abs(x) >= self.level for x in v)

    def update(self, t_ns: int, values) -> list:
        if not self.active:
            return [(t_ns, values)]
        if not self._held and not self._clipped(values):
            self._before.append((t_ns, values))
            return [(t_ns, values)]
        self._held.append((t_ns, values))
        for ax, x in enumerate(values):
            if not abs(x) >= self.level:  # as _clipped: nan is not clipped
                self._run_start_ns.pop(ax, None)
            elif (t_ns - self._run_start_ns.setdefault(ax, t_ns)) * 1e-9 > self.max_run_s:
                return self.flush()  # too long to repair (the batch leaves it too): released as it comes
        f = self.flank
        if len(self._held) > f and not any(self._clipped(v) for _, v in self._held[-f:]):
            return self.flush()
        return []

    def flush(self) -> list:
        """Release the held readings (a run without its trailing flank stays as it was)."""
        if not self._held:
            return []
        block = list(self._before) + self._held
        w, n = repair_block([b[0] for b in block], [b[1] for b in block], self.level, self.flank,
                            start=len(self._before), max_run_s=self.max_run_s)
        self.n_repaired += n
        out = [(block[k][0], tuple(float(x) for x in w[k])) for k in range(len(self._before), len(block))]
        for item in self._held[-self.flank:]:
            self._before.append(item)
        self._held = []
        return out
