"""The magnetometer calibration compiled up to its fits: per reading, and each attempt as far as a fit.

:class:`core.pdr.magcal.MagCalibrator` sees only the raw readings, never the
attitude, so the fast path runs it over the magnetometer stream before the
filter.  Per reading it checks the reading, keeps the bootstrap reservoir,
bins and stores the reading about the current centre and applies the
calibration in force: :func:`calibrate_readings`, a second implementation of
``MagCalibrator.update`` (the same float operations in the same order, so
the same floats).  Its fit attempts come at most one per ``refit_interval_s``
(about one in fifty readings at 50 Hz).  Most of them end before a fit: until
a fit is accepted the trimmed sphere through the store and the reservoir
centres the direction bins, the store is rebuilt about it, and the attempt
ends on too few samples or too little coverage (every attempt of a phone held
flat, e.g. the simulated hour walk of the throughput benchmark); with a fit in
force the store is rebuilt where samples expired and the same two checks
follow (half the attempts of the IPIN logfiles).  :func:`attempt_to_fit`
compiles that part, called from the per-reading kernel (core's ``_fit_sphere``
with ``_centred``, ``_trimmed``, ``_refill`` and ``numpy.unique``; numpy's
pairwise summation reproduced; the least squares by a Householder QR instead
of LAPACK's SVD, :func:`_lstsq4`, so the sphere's centre differs from core's
by rounding only, about 1e-15 relative, and the rest -- every calibrated
reading, the store, the decisions -- is equal on every recording tried).  An
attempt that reaches a fit is core's own ``attempt`` (ellipsoid and sphere
fits, acceptance): the kernel stops there, :class:`_Handover` writes its
state into the calibrator, the attempt runs, and the state is read back
before the kernel goes on.

The state is the calibrator's private store (slots, bin counts, counters,
centre, the calibration in force): this module is held to core's by
``tests/test_fast_path.py`` and ``tests/test_fast_magcal.py`` (every
calibrated reading, every fit, the final status and store equal on real
recordings, simulated walks and a synthetic stream).
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from desktop.fast.jit import HAVE_NUMBA, kernel

# float state: the centre, its soft iron, the offset and soft iron in force, settings
(F_C, F_CA, F_B, F_A, F_R_MIN, F_SECTOR, F_MAX_NRM2, F_REFIT_S, F_MAX_AGE_S, F_OUTLIER,
 F_MIN_COV) = 0, 3, 12, 15, 24, 25, 26, 27, 28, 29, 30
N_F = 31
# int state: flags (the reference's None), counters, the reservoir's ends (indices into the stream), settings
(I_HAS_C, I_HAS_CA, I_CAL, I_HAS_LAST, I_T_LAST, I_NEW, I_NEW_BINS, I_STORED, I_OCCUPIED, I_VALID, I_INVALID,
 I_HAS_PREV, I_T_PREV, I_HEAD, I_TAIL, I_NB, I_NS, I_PER, I_MIN_NEW, I_BOOT_NS, I_RECENT_NS, I_MIN_SAMPLES,
 I_NBINS, I_COMPILED, I_REASON, I_REASON_N) = range(26)
N_I = 26


@kernel
def calibrate_readings(t, v, i, fs, is_, slot_t, slot_m, bin_count, ring, out, ok):
    """``MagCalibrator.update`` from reading ``i`` on; returns the first reading whose fit attempt is due
    (stored, its output not yet written) or ``len(t)``.  ``ring`` holds the reservoir's readings (indices).

    With ``is_[I_COMPILED]`` the attempts run here (:func:`attempt_to_fit`) and it returns only at one that
    reaches a fit; the outcome of the last of them is left in ``is_[I_REASON]``
    (its code) and ``is_[I_REASON_N]`` (its count) for the status's reason."""
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
                if is_[I_COMPILED] == 0:
                    return i
                code, count = attempt_to_fit(t, v, i, fs, is_, slot_t, slot_m, bin_count, ring)
                if code == 3:
                    return i
                is_[I_REASON], is_[I_REASON_N] = code, count
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


# ---------------------------------------------------------------------------
# the bootstrap attempt, compiled: core's ``attempt`` while no fit is in force, up to where a fit is due


@kernel
def _block(a, lo, n):
    """numpy's ``pairwise_sum`` of ``a[lo:lo + n]`` for ``n <= 128``: eight accumulators, then the rest."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    end = n - n % 8
    while i < end:
        j = lo + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@kernel
def _pairwise(a, lo, n):
    """``numpy.add.reduce`` of ``a[lo:lo + n]`` (contiguous float64): numpy's pairwise summation, its floats.

    Blocks of at most 128 (:func:`_block`), longer runs halved at a multiple of 8 and the halves' sums added:
    numpy's ``pairwise_sum``, its recursion walked with an explicit stack (numba's cache cannot hold a
    recursive function), so that the sums below are numpy's to the bit.
    """
    if n <= 128:
        return _block(a, lo, n)
    s_lo = np.empty(64, dtype=np.int64)
    s_n = np.empty(64, dtype=np.int64)
    s_stage = np.zeros(64, dtype=np.int64)
    s_left = np.empty(64)
    s_right = np.empty(64)
    s_lo[0], s_n[0], s_stage[0] = lo, n, 0
    sp = 1
    result = 0.0
    while sp > 0:
        top = sp - 1
        m = s_n[top]
        val = 0.0
        done = False
        if m <= 128:
            val = _block(a, s_lo[top], m)
            done = True
        else:
            n2 = m // 2
            n2 -= n2 % 8
            if s_stage[top] == 0:  # the left half first
                s_stage[top] = 1
                s_lo[sp], s_n[sp], s_stage[sp] = s_lo[top], n2, 0
                sp += 1
            elif s_stage[top] == 1:  # then the right
                s_stage[top] = 2
                s_lo[sp], s_n[sp], s_stage[sp] = s_lo[top] + n2, m - n2, 0
                sp += 1
            else:
                val = s_left[top] + s_right[top]
                done = True
        if done:
            sp -= 1
            if sp == 0:
                result = val
            elif s_stage[sp - 1] == 1:
                s_left[sp - 1] = val
            else:
                s_right[sp - 1] = val
    return result


@kernel
def _lstsq4(design, rhs, k, theta):
    """Least squares ``design[:k] theta = rhs[:k]`` for 4 unknowns into ``theta``: 4 (the rank), or -1.

    Householder QR (4 reflections, back substitution): a few microseconds where LAPACK's SVD-based gelsd,
    what ``numpy.linalg.lstsq`` runs, takes 15-40 on a few hundred rows.  Its solution differs from gelsd's
    by rounding only (relative ``cond * 1e-16``, 1e-13 on the phone's samples).  Where the triangle is
    ill-conditioned (``|R_jj|`` spread over more than 1e6, far from rank 4 being in question for gelsd's
    ``rcond``) it returns -1 and the whole attempt is left to core, so the rank decisions are gelsd's.
    ``design`` and ``rhs`` are overwritten.
    """
    r_abs_min, r_abs_max = math.inf, 0.0
    for j in range(4):
        nrm2 = 0.0
        for i in range(j, k):
            nrm2 += design[i, j] * design[i, j]
        nrm = math.sqrt(nrm2)
        if nrm == 0.0:
            r_abs_min = 0.0
            break
        ajj = design[j, j]
        alpha = -nrm if ajj >= 0.0 else nrm
        design[j, j] = ajj - alpha  # the reflector v = (a_jj - alpha, a_j+1,j, ...)
        vnorm2 = nrm2 - ajj * ajj + design[j, j] * design[j, j]
        for c in range(j + 1, 4):
            dot = 0.0
            for i in range(j, k):
                dot += design[i, j] * design[i, c]
            f = 2.0 * dot / vnorm2
            for i in range(j, k):
                design[i, c] -= f * design[i, j]
        dot = 0.0
        for i in range(j, k):
            dot += design[i, j] * rhs[i]
        f = 2.0 * dot / vnorm2
        for i in range(j, k):
            rhs[i] -= f * design[i, j]
        theta[j] = alpha  # R's diagonal, for now
        r_abs_min = min(r_abs_min, abs(alpha))
        r_abs_max = max(r_abs_max, abs(alpha))
    if not r_abs_min > 1e-6 * r_abs_max:
        return -1  # ill-conditioned: core's attempt decides
    x = np.empty(4)
    for j in range(3, -1, -1):
        acc = rhs[j]
        for c in range(j + 1, 4):
            acc -= design[j, c] * x[c]
        x[j] = acc / theta[j]
    theta[:] = x
    return 4


@kernel
def _sphere(m, idx, k, out):
    """``core.pdr.magcal._fit_sphere`` on the rows ``idx[:k]`` of ``m``: 1 and ``out = (b_x, b_y, b_z, F)``, 0
    where core raises :class:`EllipsoidFitError` (fewer than 4 samples, coinciding, rank < 4, imaginary), or
    -1 where the least squares is ill-conditioned (:func:`_lstsq4`: core's attempt must decide).

    ``_centred`` (mean, RMS scale, unit samples) with core's float operations in core's order (means and row
    sums sequential, the sum of squares pairwise as numpy's), and the linear least squares
    ``|m|^2 = 2 b.m + F^2 - |b|^2`` by :func:`_lstsq4` (core: ``numpy.linalg.lstsq``; the same to rounding).
    """
    if k < 4:
        return 0
    cx, cy, cz = 0.0, 0.0, 0.0
    for r in range(k):
        j = idx[r]
        cx += m[j, 0]
        cy += m[j, 1]
        cz += m[j, 2]
    cx, cy, cz = cx / k, cy / k, cz / k
    d = np.empty((k, 3))
    sq = np.empty(k)
    for r in range(k):
        j = idx[r]
        dx, dy, dz = m[j, 0] - cx, m[j, 1] - cy, m[j, 2] - cz
        d[r, 0], d[r, 1], d[r, 2] = dx, dy, dz
        sq[r] = dx * dx + dy * dy + dz * dz
    s = math.sqrt(_pairwise(sq, np.int64(0), k) / k)  # not a literal 0: one compile of _pairwise
    if not s > 1e-9:
        return 0
    design = np.empty((k, 4))
    rhs = np.empty(k)
    for r in range(k):
        x, y, z = d[r, 0] / s, d[r, 1] / s, d[r, 2] / s
        design[r, 0], design[r, 1], design[r, 2], design[r, 3] = x * 2.0, y * 2.0, z * 2.0, 1.0
        rhs[r] = x * x + y * y + z * z
    theta = np.empty(4)
    if _lstsq4(design, rhs, k, theta) < 0:
        return -1
    bx, by, bz = theta[0], theta[1], theta[2]
    r2 = theta[3] + (bx * bx + by * by + bz * bz)
    if not r2 > 0.0:
        return 0
    out[0], out[1], out[2], out[3] = cx + s * bx, cy + s * by, cz + s * bz, s * math.sqrt(r2)
    return 1


@kernel
def _inliers(m, k, res, limit, mask):
    """``| |m_i - b| - F | <= limit F`` for the first ``k`` rows of ``m`` (a sphere's residuals); their count."""
    bx, by, bz, f = res[0], res[1], res[2], res[3]
    lim = limit * f
    n_in = 0
    for i in range(k):
        dx, dy, dz = m[i, 0] - bx, m[i, 1] - by, m[i, 2] - bz
        ok = abs(math.sqrt(dx * dx + dy * dy + dz * dz) - f) <= lim
        mask[i] = ok
        if ok:
            n_in += 1
    return n_in


@kernel
def _trimmed_sphere(t, m, k, min_samples, limit, out):
    """``MagCalibrator._trimmed(_fit_sphere, m[:k], t[:k])``'s fit into ``out``: 1, 0 where core's raises, or -1
    where a least squares on the way is ill-conditioned (core's attempt must run).

    A start from all samples, else from the newest half or quarter with more inliers, then at most three
    refits on the inliers until they no longer change (core's docstring has the why).
    """
    idx = np.arange(k)
    ok = _sphere(m, idx, k, out)
    if ok <= 0:
        return ok
    mask = np.empty(k, dtype=np.bool_)
    n_in = _inliers(m, k, out, limit, mask)
    if n_in < k:
        order = np.argsort(t[:k], kind="mergesort")
        res_n = np.empty(4)
        mask_n = np.empty(k, dtype=np.bool_)
        for part in (2, 4):
            lo = k - k // part
            if k - lo < min_samples:
                break
            ok = _sphere(m, order[lo:], k - lo, res_n)
            if ok < 0:
                return ok
            if ok == 0:
                continue
            n_n = _inliers(m, k, res_n, limit, mask_n)
            if n_n > n_in:
                out[:] = res_n
                mask[:] = mask_n
                n_in = n_n
    new = np.empty(k, dtype=np.bool_)
    for _ in range(3):
        if n_in < min_samples or n_in == k:
            break
        sel = np.flatnonzero(mask)
        ok = _sphere(m, sel, len(sel), out)
        if ok <= 0:
            return ok
        n_new = _inliers(m, k, out, limit, new)
        same = True
        for i in range(k):
            if new[i] != mask[i]:
                same = False
                break
        if same:
            break
        mask[:] = new
        n_in = n_new
    return 1


@kernel
def attempt_to_fit(t, v, i, fs, is_, slot_t, slot_m, bin_count, ring):
    """``MagCalibrator.attempt`` at reading ``i``, compiled as far as the rejections before a fit.

    Before the first accepted fit: the store (samples younger than ``sample_max_age_s``) and the bootstrap
    reservoir, merged by time (a stored sample wins a tie), the trimmed sphere centres the bins (where it is
    plausible), and the store is rebuilt about that centre.  With a fit in force: the store is rebuilt about
    the fit (its soft iron too) only where samples expired.  Then the count and the coverage are checked.
    Returns ``(code, count)``: 0 no centre yet (``count``: the samples), 1 too few samples in the store
    (``count``: them), 2 its coverage too small (``count``: the occupied bins) -- the state then is the one
    core's attempt leaves -- or 3 a fit is due: nothing is changed, core's attempt must run (the ellipsoid
    and sphere fits and their acceptance).
    """
    tn = t[i]
    per, nb, ns = is_[I_PER], is_[I_NB], is_[I_NS]
    min_samples = is_[I_MIN_SAMPLES]
    nslot = len(slot_t)
    head, tail = is_[I_HEAD], is_[I_TAIL]
    calibrated = is_[I_CAL] != 0
    cap = nslot + tail - head
    tt = np.empty(cap, dtype=np.int64)
    mm = np.empty((cap, 3))
    c = np.int64(0)  # not a literal 0: numba would compile _trimmed_sphere (and its callees) for it too
    n_full = 0
    max_age = fs[F_MAX_AGE_S]
    for s in range(nslot):  # _stored, then keep
        ts = slot_t[s]
        if ts >= 0:
            n_full += 1
            if (tn - ts) * 1e-9 <= max_age:
                tt[c] = ts
                mm[c, 0], mm[c, 1], mm[c, 2] = slot_m[3 * s], slot_m[3 * s + 1], slot_m[3 * s + 2]
                c += 1
    cx, cy, cz = fs[F_C], fs[F_C + 1], fs[F_C + 2]
    if calibrated:
        if c == n_full:  # nothing expired: the store stays as it is (core re-bins only `not np.all(keep)`)
            occupied = is_[I_OCCUPIED]
            if c >= min_samples and occupied / is_[I_NBINS] >= fs[F_MIN_COV]:
                return 3, c  # a fit: core's
            is_[I_T_LAST], is_[I_NEW], is_[I_NEW_BINS] = tn, 0, 0
            if c < min_samples:
                return 1, c
            return 2, occupied
    else:
        if tail > head:  # the reservoir too, then numpy.unique by time (the first of equal times)
            for r in range(head, tail):
                j = ring[r]
                tt[c] = t[j]
                mm[c, 0], mm[c, 1], mm[c, 2] = v[j, 0], v[j, 1], v[j, 2]
                c += 1
            order = np.argsort(tt[:c], kind="mergesort")
            t2 = np.empty(c, dtype=np.int64)
            m2 = np.empty((c, 3))
            u = 0
            for r in range(c):
                o = order[r]
                if u > 0 and tt[o] == t2[u - 1]:
                    continue
                t2[u] = tt[o]
                m2[u, 0], m2[u, 1], m2[u, 2] = mm[o, 0], mm[o, 1], mm[o, 2]
                u += 1
            tt, mm, c = t2, m2, u
        has_c = is_[I_HAS_C]
        if c >= min_samples:
            res = np.empty(4)
            ok = _trimmed_sphere(tt, mm, c, min_samples, fs[F_OUTLIER], res)
            if ok < 0:
                return 3, c  # an ill-conditioned sphere: core's attempt
            if ok == 1 and res[3] >= fs[F_R_MIN]:
                has_c = 1
                cx, cy, cz = res[0], res[1], res[2]
        if has_c == 0:
            is_[I_T_LAST], is_[I_NEW], is_[I_NEW_BINS] = tn, 0, 0
            return 0, c
    # _refill about the centre: newest first (a stable order), each bin its samples_per_bin newest
    new_t = np.full(nslot, -1, dtype=np.int64)
    new_m = np.zeros(3 * nslot)
    counts = np.zeros(len(bin_count), dtype=np.int64)
    order = np.argsort(-tt[:c], kind="mergesort")
    r_min, scale = fs[F_R_MIN], fs[F_SECTOR]
    n_st = 0
    occupied = 0
    has_ca = is_[I_HAS_CA] != 0
    a = F_CA
    for r in range(c):
        o = order[r]
        dx, dy, dz = mm[o, 0] - cx, mm[o, 1] - cy, mm[o, 2] - cz
        if has_ca:  # _bins about a fit with soft iron
            dx, dy, dz = (fs[a] * dx + fs[a + 1] * dy + fs[a + 2] * dz,
                          fs[a + 3] * dx + fs[a + 4] * dy + fs[a + 5] * dz,
                          fs[a + 6] * dx + fs[a + 7] * dy + fs[a + 8] * dz)
        rr = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not rr >= r_min:
            continue
        band = int((dz / rr + 1.0) * 0.5 * nb)
        sector = int((math.atan2(dy, dx) + math.pi) * scale)
        k = (band if band < nb else nb - 1) * ns + (sector if sector < ns else ns - 1)
        if counts[k] >= per:
            continue
        j = k * per + counts[k]
        if counts[k] == 0:
            occupied += 1
        counts[k] += 1
        new_t[j] = tt[o]
        new_m[3 * j], new_m[3 * j + 1], new_m[3 * j + 2] = mm[o, 0], mm[o, 1], mm[o, 2]
        n_st += 1
    if n_st >= min_samples and occupied / is_[I_NBINS] >= fs[F_MIN_COV]:
        return 3, n_st  # a fit: core's
    slot_t[:] = new_t
    slot_m[:] = new_m
    bin_count[:] = counts
    is_[I_STORED], is_[I_OCCUPIED] = n_st, occupied
    is_[I_HAS_C] = 1
    fs[F_C], fs[F_C + 1], fs[F_C + 2] = cx, cy, cz
    is_[I_T_LAST], is_[I_NEW], is_[I_NEW_BINS] = tn, 0, 0
    if n_st < min_samples:
        return 1, n_st
    return 2, occupied


def _flat(rows) -> list:
    return [float(x) for row in rows for x in row]


class _Handover:
    """The kernel's state, read from and written into a :class:`core.pdr.magcal.MagCalibrator` around its attempts."""

    def __init__(self, cal, t: np.ndarray, v: np.ndarray):
        self.t, self.v = t, v
        self.fs = np.zeros(N_F)
        self.is_ = np.zeros(N_I, dtype=np.int64)
        self.ring = np.zeros(max(len(t), 1), dtype=np.int64)
        ks = cal.kernel_settings
        self.fs[F_R_MIN], self.fs[F_SECTOR], self.fs[F_MAX_NRM2] = ks["r_min_uT"], ks["sector_scale"], ks["max_nrm2"]
        self.fs[F_REFIT_S] = cal.refit_interval_s
        self.fs[F_MAX_AGE_S], self.fs[F_OUTLIER], self.fs[F_MIN_COV] = (
            cal.sample_max_age_s, cal.outlier_fraction, cal.min_coverage)
        self.is_[[I_NB, I_NS, I_PER, I_MIN_NEW, I_BOOT_NS, I_RECENT_NS, I_MIN_SAMPLES, I_NBINS]] = (
            cal.bin_bands, cal.n_sectors, cal.samples_per_bin, cal.refit_min_new_samples, ks["bootstrap_ns"],
            ks["recent_dt_ns"], cal.min_samples, cal.n_bins)
        self.read(cal)

    def read(self, cal) -> None:
        """The calibrator's state (:meth:`MagCalibrator.state`) into the kernel's (after its reset or an attempt)."""
        fs, is_, st = self.fs, self.is_, cal.state()
        self.slot_t = np.array(st["_slot_t"], dtype=np.int64)
        self.slot_m = np.array(st["_slot_m"], dtype=np.float64)
        self.bin_count = np.array(st["_bin_count"], dtype=np.int64)
        centre, centre_a = st["_centre"], st["_centre_a"]
        is_[I_HAS_C] = centre is not None
        if centre is not None:
            fs[F_C:F_C + 3] = centre
        is_[I_HAS_CA] = centre_a is not None
        if centre_a is not None:
            fs[F_CA:F_CA + 9] = _flat(centre_a)
        is_[I_CAL] = st["_calibrated"]
        fs[F_B:F_B + 3] = st["_b"]
        fs[F_A:F_A + 9] = _flat(st["_a"])
        is_[I_HAS_LAST] = st["_t_last_attempt"] is not None
        is_[I_T_LAST] = st["_t_last_attempt"] or 0
        is_[I_NEW], is_[I_NEW_BINS] = st["_new_since"], st["_new_bins_since"]
        is_[I_STORED], is_[I_OCCUPIED] = st["_n_stored"], st["_occupied"]
        is_[I_VALID], is_[I_INVALID] = st["n_valid"], st["n_invalid"]
        is_[I_HAS_PREV] = st["_t_prev"] is not None
        is_[I_T_PREV] = st["_t_prev"] or 0
        if len(st["_recent"]) == 0:  # emptied by an accepted fit (or a reset); else the attempt left it as it was
            is_[I_HEAD] = is_[I_TAIL]

    def write(self, cal, reason: str | None = None) -> None:
        """The kernel's state into the calibrator (before an attempt, and at the end, with the kernel's ``reason``
        of its last attempt), through :meth:`MagCalibrator.restore_state`."""
        is_ = self.is_
        values = {
            "_centre": tuple(float(x) for x in self.fs[F_C:F_C + 3]) if is_[I_HAS_C] else None,  # bootstrap attempts
            "_slot_t": array("q", self.slot_t.tobytes()), "_slot_m": array("d", self.slot_m.tobytes()),
            "_bin_count": self.bin_count.tolist()}
        if cal.calibrated:
            values["_recent"], values["_recent_m"] = array("q"), array("d")
        else:
            idx = self.ring[is_[I_HEAD]:is_[I_TAIL]]
            values["_recent"] = array("q", self.t[idx].tobytes())
            values["_recent_m"] = array("d", np.ascontiguousarray(self.v[idx]).tobytes())
        values["_t_last_attempt"] = int(is_[I_T_LAST]) if is_[I_HAS_LAST] else None
        values["_new_since"], values["_new_bins_since"] = int(is_[I_NEW]), int(is_[I_NEW_BINS])
        values["_n_stored"], values["_occupied"] = int(is_[I_STORED]), int(is_[I_OCCUPIED])
        values["n_valid"], values["n_invalid"] = int(is_[I_VALID]), int(is_[I_INVALID])
        values["_t_prev"] = int(is_[I_T_PREV]) if is_[I_HAS_PREV] else None
        if reason is not None:
            values["_reason"] = reason
        cal.restore_state(values)


def calibrate_stream(cal, t_ns: np.ndarray, mag_b: np.ndarray, compiled_attempts: bool | None = None):
    """``cal`` (reset first) over a whole magnetometer stream: the calibrated readings (n, 3) and whether a fit
    was in force at each, as ``MagCalibrator.update`` reading by reading gives them; ``cal`` ends in the state
    those updates leave.

    ``compiled_attempts`` (default: where numba is installed) runs the fit attempts with
    :func:`attempt_to_fit` as far as it goes (to a rejection before a fit, or to a fit, which is core's);
    without it every attempt is core's ``attempt`` (numpy, faster than the kernel run as plain Python).
    """
    if compiled_attempts is None:
        compiled_attempts = HAVE_NUMBA
    cal.reset()
    t = np.ascontiguousarray(t_ns, dtype=np.int64)
    v = np.ascontiguousarray(mag_b, dtype=np.float64).reshape(len(t), 3)
    out = np.empty((len(t), 3))
    ok = np.zeros(len(t), dtype=np.bool_)
    h = _Handover(cal, t, v)
    h.is_[I_COMPILED], h.is_[I_REASON] = bool(compiled_attempts), -1
    i = 0
    while True:
        i = calibrate_readings(t, v, i, h.fs, h.is_, h.slot_t, h.slot_m, h.bin_count, h.ring, out, ok)
        if i >= len(t):
            break
        h.write(cal)
        cal.attempt(int(t[i]))
        h.read(cal)
        h.is_[I_REASON] = -1  # core's attempt set the reason
        out[i] = cal.apply_tuple(float(v[i, 0]), float(v[i, 1]), float(v[i, 2]))
        ok[i] = cal.calibrated
        i += 1
    code, count = int(h.is_[I_REASON]), int(h.is_[I_REASON_N])
    reason = None  # -1: core's attempt set it (or none was made)
    if code == 2:
        reason = f"coverage {count / cal.n_bins:.2f} < {cal.min_coverage:.2f}"
    elif code >= 0:
        reason = f"too few samples ({count} < {cal.min_samples})"
    h.write(cal, reason)
    return out, ok
