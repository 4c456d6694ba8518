"""The magnetometer calibration's per-reading part as a compiled loop; its fits stay core's (Python).

:class:`core.pdr.magcal.MagCalibrator` sees only the raw readings, never the
attitude, so the fast path runs it over the magnetometer stream before the
filter.  Per reading it checks the reading, keeps the bootstrap reservoir,
bins and stores the reading about the current centre and applies the
calibration in force: :func:`calibrate_readings`, a second implementation of
``MagCalibrator.update`` (the same float operations in the same order, so
the same floats).  Its fit attempts -- at most one per ``refit_interval_s``,
about one in fifty readings at 50 Hz -- are core's own ``_attempt``: the
kernel stops at a reading whose attempt is due, :class:`_Handover` writes
the kernel's state into the calibrator, the attempt runs (sphere and ellipsoid
fits, re-binning), and the state is read back before the kernel goes on.

The state is the calibrator's private store (slots, bin counts, counters,
centre, the calibration in force): this module is held to core's by
``tests/test_fast_path.py`` (every calibrated reading, every fit and the final
status equal on a real recording's magnetometer stream).
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from core.pdr import magcal as core_magcal
from desktop.fast.jit import kernel

# float state: the centre, its soft iron, the offset and soft iron in force, settings
F_C, F_CA, F_B, F_A, F_R_MIN, F_SECTOR, F_MAX_NRM2, F_REFIT_S = 0, 3, 12, 15, 24, 25, 26, 27
N_F = 28
# int state: flags (the reference's None), counters, the reservoir's ends (indices into the stream), settings
(I_HAS_C, I_HAS_CA, I_CAL, I_HAS_LAST, I_T_LAST, I_NEW, I_NEW_BINS, I_STORED, I_OCCUPIED, I_VALID, I_INVALID,
 I_HAS_PREV, I_T_PREV, I_HEAD, I_TAIL, I_NB, I_NS, I_PER, I_MIN_NEW, I_BOOT_NS, I_RECENT_NS) = range(21)
N_I = 21


@kernel
def calibrate_readings(t, v, i, fs, is_, slot_t, slot_m, bin_count, ring, out, ok):
    """``MagCalibrator.update`` from reading ``i`` on; returns the first reading whose fit attempt is due
    (stored, its output not yet written) or ``len(t)``.  ``ring`` holds the reservoir's readings (indices)."""
    n = len(t)
    nb, ns, per = is_[I_NB], is_[I_NS], is_[I_PER]
    while i < n:
        ti = t[i]
        mx, my, mz = v[i, 0], v[i, 1], v[i, 2]
        nrm2 = mx * mx + my * my + mz * mz
        if not (math.isfinite(nrm2) and nrm2 <= fs[F_MAX_NRM2]):
            is_[I_INVALID] += 1
        else:
            is_[I_VALID] += 1
            if is_[I_CAL] == 0:
                head, tail = is_[I_HEAD], is_[I_TAIL]
                if head == tail or ti - t[ring[tail - 1]] >= is_[I_RECENT_NS]:
                    ring[tail] = i
                    tail += 1
                    t_old = ti - is_[I_BOOT_NS]
                    while t[ring[head]] < t_old:
                        head += 1
                    is_[I_HEAD], is_[I_TAIL] = head, tail
            is_[I_HAS_PREV], is_[I_T_PREV] = 1, ti
            if is_[I_HAS_C] != 0:
                dx, dy, dz = mx - fs[F_C], my - fs[F_C + 1], mz - fs[F_C + 2]
                if is_[I_HAS_CA] != 0:
                    a = F_CA
                    dx, dy, dz = (fs[a] * dx + fs[a + 1] * dy + fs[a + 2] * dz,
                                  fs[a + 3] * dx + fs[a + 4] * dy + fs[a + 5] * dz,
                                  fs[a + 6] * dx + fs[a + 7] * dy + fs[a + 8] * dz)
                r = math.sqrt(dx * dx + dy * dy + dz * dz)
                if r >= fs[F_R_MIN]:
                    band = int((dz / r + 1.0) * 0.5 * nb)
                    sector = int((math.atan2(dy, dx) + math.pi) * fs[F_SECTOR])
                    k = (band if band < nb else nb - 1) * ns + (sector if sector < ns else ns - 1)
                    base = k * per
                    j = base
                    oldest = slot_t[base]
                    for s in range(base + 1, base + per):
                        if slot_t[s] < oldest:  # empty slots (-1) come first, then the oldest
                            oldest, j = slot_t[s], s
                    if oldest < 0:
                        is_[I_STORED] += 1
                        if bin_count[k] == 0:
                            is_[I_OCCUPIED] += 1
                            is_[I_NEW_BINS] += 1
                        bin_count[k] += 1
                    slot_t[j] = ti
                    slot_m[3 * j], slot_m[3 * j + 1], slot_m[3 * j + 2] = mx, my, mz
                    is_[I_NEW] += 1
            if is_[I_HAS_LAST] == 0:
                is_[I_HAS_LAST], is_[I_T_LAST] = 1, ti
            elif ((is_[I_NEW] >= is_[I_MIN_NEW] or is_[I_NEW_BINS] > 0 or is_[I_HAS_C] == 0)
                  and (ti - is_[I_T_LAST]) * 1e-9 >= fs[F_REFIT_S]):
                return i
        if is_[I_CAL] != 0:
            dx, dy, dz = mx - fs[F_B], my - fs[F_B + 1], mz - fs[F_B + 2]
            a = F_A
            out[i, 0] = fs[a] * dx + fs[a + 1] * dy + fs[a + 2] * dz
            out[i, 1] = fs[a + 3] * dx + fs[a + 4] * dy + fs[a + 5] * dz
            out[i, 2] = fs[a + 6] * dx + fs[a + 7] * dy + fs[a + 8] * dz
            ok[i] = True
        else:
            out[i, 0], out[i, 1], out[i, 2] = mx, my, mz
        i += 1
    return n


def _flat(rows) -> list:
    return [float(x) for row in rows for x in row]


class _Handover:
    """The kernel's state, read from and written into a :class:`core.pdr.magcal.MagCalibrator` around its attempts."""

    def __init__(self, cal, t: np.ndarray, v: np.ndarray):
        self.t, self.v = t, v
        self.fs = np.zeros(N_F)
        self.is_ = np.zeros(N_I, dtype=np.int64)
        self.ring = np.zeros(max(len(t), 1), dtype=np.int64)
        self.fs[F_R_MIN], self.fs[F_SECTOR], self.fs[F_MAX_NRM2] = cal._r_min, cal._sector_scale, cal._max_nrm2
        self.fs[F_REFIT_S] = cal.refit_interval_s
        self.is_[[I_NB, I_NS, I_PER, I_MIN_NEW, I_BOOT_NS, I_RECENT_NS]] = (
            cal.bin_bands, cal.n_sectors, cal.samples_per_bin, cal.refit_min_new_samples, cal._bootstrap_ns,
            core_magcal._RECENT_DT_NS)
        self.read(cal)

    def read(self, cal) -> None:
        """The calibrator's state into the kernel's (after its reset or an attempt)."""
        fs, is_ = self.fs, self.is_
        self.slot_t = np.array(cal._slot_t, dtype=np.int64)
        self.slot_m = np.array(cal._slot_m, dtype=np.float64)
        self.bin_count = np.array(cal._bin_count, dtype=np.int64)
        is_[I_HAS_C] = cal._centre is not None
        if cal._centre is not None:
            fs[F_C:F_C + 3] = cal._centre
        is_[I_HAS_CA] = cal._centre_a is not None
        if cal._centre_a is not None:
            fs[F_CA:F_CA + 9] = _flat(cal._centre_a)
        is_[I_CAL] = cal._calibrated
        fs[F_B:F_B + 3] = cal._b
        fs[F_A:F_A + 9] = _flat(cal._a)
        is_[I_HAS_LAST] = cal._t_last_attempt is not None
        is_[I_T_LAST] = cal._t_last_attempt or 0
        is_[I_NEW], is_[I_NEW_BINS] = cal._new_since, cal._new_bins_since
        is_[I_STORED], is_[I_OCCUPIED] = cal._n_stored, cal._occupied
        is_[I_VALID], is_[I_INVALID] = cal.n_valid, cal.n_invalid
        is_[I_HAS_PREV] = cal._t_prev is not None
        is_[I_T_PREV] = cal._t_prev or 0
        if len(cal._recent) == 0:  # emptied by an accepted fit (or a reset); else the attempt left it as it was
            is_[I_HEAD] = is_[I_TAIL]

    def write(self, cal) -> None:
        """The kernel's state into the calibrator (before an attempt, and at the end)."""
        is_ = self.is_
        cal._slot_t, cal._slot_m = array("q", self.slot_t.tobytes()), array("d", self.slot_m.tobytes())
        cal._bin_count = self.bin_count.tolist()
        if cal._calibrated:
            cal._recent, cal._recent_m = array("q"), array("d")
        else:
            idx = self.ring[is_[I_HEAD]:is_[I_TAIL]]
            cal._recent = array("q", self.t[idx].tobytes())
            cal._recent_m = array("d", np.ascontiguousarray(self.v[idx]).tobytes())
        cal._t_last_attempt = int(is_[I_T_LAST]) if is_[I_HAS_LAST] else None
        cal._new_since, cal._new_bins_since = int(is_[I_NEW]), int(is_[I_NEW_BINS])
        cal._n_stored, cal._occupied = int(is_[I_STORED]), int(is_[I_OCCUPIED])
        cal.n_valid, cal.n_invalid = int(is_[I_VALID]), int(is_[I_INVALID])
        cal._t_prev = int(is_[I_T_PREV]) if is_[I_HAS_PREV] else None


def calibrate_stream(cal, t_ns: np.ndarray, mag_b: np.ndarray):
    """``cal`` (reset first) over a whole magnetometer stream: the calibrated readings (n, 3) and whether a fit
    was in force at each, as ``MagCalibrator.update`` reading by reading gives them; ``cal`` ends in the state
    those updates leave."""
    cal.reset()
    t = np.ascontiguousarray(t_ns, dtype=np.int64)
    v = np.ascontiguousarray(mag_b, dtype=np.float64).reshape(len(t), 3)
    out = np.empty((len(t), 3))
    ok = np.zeros(len(t), dtype=np.bool_)
    h = _Handover(cal, t, v)
    i = 0
    while True:
        i = calibrate_readings(t, v, i, h.fs, h.is_, h.slot_t, h.slot_m, h.bin_count, h.ring, out, ok)
        if i >= len(t):
            break
        h.write(cal)
        cal._attempt(int(t[i]))
        h.read(cal)
        out[i] = cal._apply_tuple(float(v[i, 0]), float(v[i, 1]), float(v[i, 2]))
        ok[i] = cal.calibrated
        i += 1
    h.write(cal)
    return out, ok
