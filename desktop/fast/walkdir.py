"""The walking-direction stage over the whole grid: one compiled pass instead of an ``update`` per grid sample.

Second implementation of :class:`core.pdr.walkdir.WalkingDirection` fed every grid sample (as
``Pipeline`` feeds it and ``desktop.fast.gates.StepRelease`` fed it in Python): the acceleration to ENU with
the attitude (``a_n = R(q) a_b``), the vertical's slow mean removed and leaked into ``v_z``, the
``delay_s`` buffer pairing each sample with the smoothed forward vector of its time, strides from one step
event to the next but one, each judged (duration, forward axis, samples, turn, still, the raw or the
coherent axis and its anisotropy, the sign from ``cov(a_h . e, v_z) < 0``) and the accepted ones folded into
the per-axis circular means with forgetting; a gap of ``reset_after_gap_s`` without an accepted stride
forgets them (core's module docstring has the gait physics and the why).  :func:`walk_kernel` does it with
core's float operations in core's order (``math.hypot`` as CPython 3.11 computes it, :func:`_hypot`), so the
same floats.

What the pipeline reads from the stage at a step is the estimate of the smoother's current axis after the
grid sample the step's heading is made at (``step_heading``/``applies``/``offset_rad`` read nothing else):
:func:`walking_direction_over_grid` returns a :class:`WalkdirTrace` holding that axis's accumulators after
every grid sample; :meth:`WalkdirTrace.at` puts them into the ``WalkingDirection`` object, so that core's
own ``step_heading`` (with whatever carry mode is in force) gives the step's heading, and at the last grid
sample it leaves the object in the state the updates leave (buffer, open stride, every axis, counters,
the per-stride records, ``last_estimate``), so that its diagnostics are the same.
``tests/test_fast_walkdir.py`` holds it to ``WalkingDirection.update`` sample by sample.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from core.pdr.walkdir import AXIS_METHODS, REJECT_REASONS, _AxisState
from desktop.fast.jit import HAVE_NUMBA, kernel

# float settings
(F_DT, F_LEAK, F_ALPHA, F_FORGET, F_MIN_FWD, F_MIN_STRIDE, F_MAX_STRIDE, F_RATE, F_MAX_TURN, F_MIN_TR,
 F_PCA_ANISO, F_MIN_COH, F_MIN_ANISO) = range(13)
# float state: the mean of the vertical, v_z, the open stride's sums (14) and its first forward unit vector
F_MEAN_U, F_VZ, F_SUMS, F_FWD0 = 13, 14, 15, 29
# a float setting added after the state (issue #25): core's ``phase_axis_below_ratio``
F_PHASE_RATIO = 31
N_F = 32
# int settings, then int state
(I_DELAY_N, I_GAP_NS, I_METHOD, I_HAS_LAST, I_LAST_NS, I_KEY, I_STEPS, I_T0, I_SKIPPED, I_HAS_FWD0, I_N_GAP,
 I_N_STRIDES, I_N_ACCEPTED, I_N_SIGN, I_N_NONFINITE, I_HEAD, I_TAIL, I_N_REC, I_NEXT_ORDER, I_HAS_EST,
 I_EST_KEY, I_REJ) = range(22)
N_I = I_REJ + len(REJECT_REASONS)
# the accumulators of an axis (core's _AxisState): c2, s2, w, w2, gx, gy (floats) and n
A_C2, A_S2, A_W, A_W2, A_GX, A_GY = range(6)
# per-stride records: ints (t_ns, outcome: 0 accepted or 1 + index in REJECT_REASONS, method, sign, axis)
R_T, R_OUT, R_METHOD, R_SIGN, R_AXIS = range(5)
# and floats
R_TURN, R_ANISO, R_COHERENCE, R_AXIS_ANISO, R_AXIS_OFFSET, R_CORR, R_OFFSET = range(7)
_T27 = 134217729.0  # 2**27 + 1: Veltkamp's split of a double into two halves


@kernel
def _hypot(a, b):
    """``math.hypot(a, b)`` as CPython 3.11 computes it (``vector_norm``: scaled, the squares summed without
    loss, one differential correction), so that the compiled kernel has Python's floats (the C library's
    ``hypot`` differs from it in the last bit now and then)."""
    a, b = abs(a), abs(b)
    mx = a if a > b else b
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if a != a or b != b:
        return math.nan
    if mx == 0.0:
        return mx
    _, e = math.frexp(mx)
    if e < -1020:  # subnormal: CPython rescales by DBL_MIN first; no forward vector or acceleration is that small
        return math.hypot(a, b)
    scale = math.ldexp(1.0, -e)
    csum = 1.0
    frac = 0.0
    for x in (a, b):
        x *= scale
        t = x * _T27
        hi = t - (t - x)
        lo = x - hi
        y = hi * hi
        old = csum
        csum += y
        frac += (old - csum) + y
        y = 2.0 * hi * lo
        old = csum
        csum += y
        frac += (old - csum) + y
        y = lo * lo
        old = csum
        csum += y
        frac += (old - csum) + y
    h = math.sqrt(csum - 1.0 + frac)
    t = h * _T27
    hi = t - (t - h)
    lo = h - hi
    y = -hi * hi
    old = csum
    csum += y
    frac += (old - csum) + y
    y = -2.0 * hi * lo
    old = csum
    csum += y
    frac += (old - csum) + y
    y = -lo * lo
    old = csum
    csum += y
    frac += (old - csum) + y
    x = csum - 1.0 + frac
    return (h + x / (2.0 * h)) / scale


@kernel
def _wrap(a):
    """:func:`core.conventions.wrap_angle` of a float: [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@kernel
def _anisotropy(cxx, cyy, cxy):
    """:func:`core.pdr.walkdir._anisotropy`: larger over smaller eigenvalue of [[cxx, cxy], [cxy, cyy]]."""
    tr = cxx + cyy
    d = _hypot(cxx - cyy, 2.0 * cxy)
    l1, l2 = 0.5 * (tr + d), 0.5 * (tr - d)
    if l1 <= 0.0:
        return 1.0
    return l1 / l2 if l2 > 1e-12 * l1 else 1e12


@kernel
def _offset_of(ax, k):
    """``WalkingDirection._offset_of`` of axis ``k``'s accumulators: the axis, turned to the sign evidence."""
    theta = 0.5 * math.atan2(ax[k, A_S2], ax[k, A_C2])
    if ax[k, A_GX] * math.cos(theta) + ax[k, A_GY] * math.sin(theta) < 0.0:
        theta += math.pi
    return _wrap(theta)


@kernel
def _pos(v):
    """Python's ``max(v, 0.0)`` (``v`` itself unless 0.0 is larger: -0.0 and nan stay)."""
    return 0.0 if 0.0 > v else v


@kernel
def _judge(t_s, fe, fn, norm, fs, is_, ax, ax_n, ax_order, rec_i, rec_f, r):
    """``WalkingDirection._judge`` of the stride closing at ``t_s`` into record ``r``: 0 accepted (the axis's
    accumulators updated), else 1 + the reason's index in ``REJECT_REASONS``."""
    dur = (t_s - is_[I_T0]) * 1e-9
    if not fs[F_MIN_STRIDE] <= dur <= fs[F_MAX_STRIDE]:
        return 1  # duration
    s = F_SUMS
    n = fs[s]
    if is_[I_HAS_FWD0] == 0 or norm < fs[F_MIN_FWD] or is_[I_SKIPPED] > 0.2 * (n + 1):
        return 7  # vertical_axis
    if n < 0.5 * dur * fs[F_RATE] or n < 10:
        return 2  # samples
    e0, n0 = fs[F_FWD0], fs[F_FWD0 + 1]
    turn = math.atan2(e0 * fn - n0 * fe, e0 * fe + n0 * fn)
    rec_f[r, R_TURN] = turn
    if abs(turn) > fs[F_MAX_TURN]:
        return 6  # turning
    inv = 1.0 / n
    mx, my, mv = fs[s + 1] * inv, fs[s + 2] * inv, fs[s + 6] * inv
    cxx = _pos(fs[s + 3] * inv - mx * mx)
    cyy = _pos(fs[s + 4] * inv - my * my)
    cxy = fs[s + 5] * inv - mx * my
    cxv = fs[s + 7] * inv - mx * mv
    cyv = fs[s + 8] * inv - my * mv
    cvv = _pos(fs[s + 9] * inv - mv * mv)
    tr = cxx + cyy
    if tr < fs[F_MIN_TR]:
        return 3  # still
    raw_aniso = _anisotropy(cxx, cyy, cxy)
    rec_f[r, R_ANISO] = raw_aniso
    den = math.sqrt(tr * cvv)
    gx, gy = 0.0, 0.0
    if den > 1e-12:
        gx, gy = -cxv / den, -cyv / den
    mu = fs[s + 10] * inv
    cuu = _pos(fs[s + 13] * inv - mu * mu)
    du = math.sqrt(tr * cuu)
    hx, hy = 0.0, 0.0
    if du > 1e-12:
        hx, hy = (fs[s + 11] * inv - mx * mu) / du, (fs[s + 12] * inv - my * mu) / du
    kxx, kyy, kxy = gx * gx + hx * hx, gy * gy + hy * hy, gx * gy + hx * hy
    coherence = kxx + kyy
    rec_f[r, R_COHERENCE] = coherence
    method = is_[I_METHOD]
    if method == 0:  # auto
        method = 1 if raw_aniso >= fs[F_PCA_ANISO] else 2
    if method == 2 and fs[F_PHASE_RATIO] > 0.0 and (gx != 0.0 or gy != 0.0):
        # core's phase_axis_below_ratio: the phase axis where it lies on the raw ellipse's minor side
        g2 = gx * gx + gy * gy
        along_g = (cxx * gx * gx + 2.0 * cxy * gx * gy + cyy * gy * gy) / g2
        if along_g < fs[F_PHASE_RATIO] * (tr - along_g):
            method = 3
    rec_i[r, R_METHOD] = method
    if method == 1:  # pca
        theta = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)
        aniso = raw_aniso
    else:
        if coherence < fs[F_MIN_COH]:
            return 4  # incoherent
        aniso = _anisotropy(kxx, kyy, kxy)
        theta = 0.5 * math.atan2(2.0 * kxy, kxx - kyy) if method == 2 else math.atan2(gy, gx)
    rec_f[r, R_AXIS_ANISO] = aniso
    if aniso < fs[F_MIN_ANISO]:
        return 5  # isotropic
    rec_f[r, R_AXIS_OFFSET] = theta
    ct, st = math.cos(theta), math.sin(theta)
    along = gx * ct + gy * st
    rec_f[r, R_CORR] = along
    key = is_[I_KEY]
    rec_i[r, R_AXIS] = key
    sign = 1 if along >= 0.0 else -1
    rec_i[r, R_SIGN] = sign
    offset = theta if sign > 0 else _wrap(theta + math.pi)
    rec_f[r, R_OFFSET] = offset
    is_[I_HAS_LAST], is_[I_LAST_NS] = 1, t_s
    if ax_n[key] == 0:  # a new state (a fresh one, or after a gap's reset): it goes last in the dict
        ax[key, :] = 0.0
        ax_order[key] = is_[I_NEXT_ORDER]
        is_[I_NEXT_ORDER] += 1
    had = ax_n[key] > 0
    before = _offset_of(ax, key) if had else 0.0
    f = fs[F_FORGET]
    ax[key, A_C2] = f * ax[key, A_C2] + math.cos(2.0 * theta)
    ax[key, A_S2] = f * ax[key, A_S2] + math.sin(2.0 * theta)
    ax[key, A_W] = f * ax[key, A_W] + 1.0
    ax[key, A_W2] = f * f * ax[key, A_W2] + 1.0
    ax[key, A_GX] = f * ax[key, A_GX] + gx
    ax[key, A_GY] = f * ax[key, A_GY] + gy
    ax_n[key] += 1
    is_[I_N_ACCEPTED] += 1
    if had and abs(_wrap(offset - before)) > 0.5 * math.pi:
        is_[I_N_SIGN] += 1
    return 0


@kernel
def walk_kernel(t, q, acc, fe, fn, step, axis, fs, is_, ax, ax_n, ax_order, smp, fifo, rec_i, rec_f, est,
                cur, cur_n, cur_key):
    """``WalkingDirection.update`` over grid samples ``0..n-1`` (``t`` int64 ns, ``q`` (n, 4), ``acc`` (n, 3),
    the smoothed forward vector ``fe``, ``fn``, ``step`` flags, ``axis`` ids), from the state in ``fs``/``is_``
    (the axes' accumulators ``ax`` (k, 6), ``ax_n``, their dict order ``ax_order``).  Writes the current axis
    (``cur_key``, -1 for none) and its accumulators after each sample into ``cur`` (n, 6) and ``cur_n`` (0: no
    estimate), each valid sample's
    ``(a_east, a_north, a_up - mean, v_z)`` into ``smp`` and its index into the delay buffer ``fifo``, each
    closed stride into ``rec_i``/``rec_f``, and at a gap's reset the estimate being forgotten into ``est``."""
    delay_n = is_[I_DELAY_N]
    dt, leak, alpha = fs[F_DT], fs[F_LEAK], fs[F_ALPHA]
    for j in range(len(t)):
        ax_, ay_, az_ = acc[j, 0], acc[j, 1], acc[j, 2]
        if not (math.isfinite(ax_) and math.isfinite(ay_) and math.isfinite(az_) and math.isfinite(fe[j])
                and math.isfinite(fn[j])):
            is_[I_N_NONFINITE] += 1
        else:
            w, x, y, z = q[j, 0], q[j, 1], q[j, 2], q[j, 3]
            r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
            r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
            r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
            ae = r00 * ax_ + r01 * ay_ + r02 * az_
            an = r10 * ax_ + r11 * ay_ + r12 * az_
            au = r20 * ax_ + r21 * ay_ + r22 * az_
            if not (math.isfinite(ae) and math.isfinite(an) and math.isfinite(au)):
                is_[I_N_NONFINITE] += 1
            else:
                m = fs[F_MEAN_U]
                if m != m:
                    m = au
                m += alpha * (au - m)
                fs[F_MEAN_U] = m
                fs[F_VZ] = leak * fs[F_VZ] + (au - m) * dt
                if is_[I_HAS_LAST] != 0 and t[j] - is_[I_LAST_NS] > is_[I_GAP_NS]:
                    k = is_[I_KEY]  # the estimate forgotten: the current axis's, before this sample's axis
                    is_[I_HAS_EST] = 1
                    is_[I_EST_KEY] = k
                    if k >= 0 and ax_n[k] > 0:
                        est[:6] = ax[k, :]
                        est[6] = ax_n[k]
                    else:
                        est[6] = 0.0
                    ax_n[:] = 0
                    is_[I_HAS_LAST] = 0
                    is_[I_N_GAP] += 1
                smp[j, 0], smp[j, 1], smp[j, 2], smp[j, 3] = ae, an, au - m, fs[F_VZ]
                fifo[is_[I_TAIL]] = j
                is_[I_TAIL] += 1
                if axis[j] != is_[I_KEY]:
                    is_[I_KEY] = axis[j]
                    is_[I_STEPS] = -1  # the open stride mixed two axes
                if is_[I_TAIL] - is_[I_HEAD] > delay_n:
                    i = fifo[is_[I_HEAD]]
                    is_[I_HEAD] += 1
                    _paired(t, step, smp, i, fe[j], fn[j], fs, is_, ax, ax_n, ax_order, rec_i, rec_f)
        k = is_[I_KEY]
        cur_key[j] = k
        if k >= 0 and ax_n[k] > 0:
            cur[j, :] = ax[k, :]
            cur_n[j] = ax_n[k]
        else:
            cur_n[j] = 0


@kernel
def _paired(t, step, smp, i, fe, fn, fs, is_, ax, ax_n, ax_order, rec_i, rec_f):
    """``WalkingDirection._paired``: delayed sample ``i`` with the forward vector of its time (and ``_boundary``)."""
    norm = _hypot(fe, fn)
    if step[i]:
        if is_[I_STEPS] < 0 or is_[I_STEPS] + 1 >= 2:
            if is_[I_STEPS] >= 0:  # _close
                is_[I_N_STRIDES] += 1
                r = is_[I_N_REC]
                is_[I_N_REC] += 1
                rec_i[r, :] = 0
                rec_f[r, :] = math.nan
                rec_i[r, R_T] = t[i]
                out = _judge(t[i], fe, fn, norm, fs, is_, ax, ax_n, ax_order, rec_i, rec_f, r)
                rec_i[r, R_OUT] = out
                if out > 0:
                    is_[I_REJ + out - 1] += 1
            is_[I_STEPS] = 0
            is_[I_T0] = t[i]
            if norm >= fs[F_MIN_FWD]:
                is_[I_HAS_FWD0] = 1
                fs[F_FWD0], fs[F_FWD0 + 1] = fe / norm, fn / norm
            else:
                is_[I_HAS_FWD0] = 0
            is_[I_SKIPPED] = 0
            fs[F_SUMS:F_SUMS + 14] = 0.0
        else:
            is_[I_STEPS] += 1
    if is_[I_STEPS] < 0:
        return
    if norm < fs[F_MIN_FWD]:
        is_[I_SKIPPED] += 1
        return
    ue, un = fe / norm, fn / norm
    ae, an, au, vz = smp[i, 0], smp[i, 1], smp[i, 2], smp[i, 3]
    x = ae * ue + an * un
    y = -ae * un + an * ue
    s = F_SUMS
    fs[s] += 1.0
    fs[s + 1] += x
    fs[s + 2] += y
    fs[s + 3] += x * x
    fs[s + 4] += y * y
    fs[s + 5] += x * y
    fs[s + 6] += vz
    fs[s + 7] += x * vz
    fs[s + 8] += y * vz
    fs[s + 9] += vz * vz
    fs[s + 10] += au
    fs[s + 11] += x * au
    fs[s + 12] += y * au
    fs[s + 13] += au * au


_METHODS = ("auto", "pca", "coherent", "phase")
assert set(_METHODS) == set(AXIS_METHODS)


def _axis_state(row, n) -> _AxisState:
    # the kernel's rows hold c2, s2, w, w2, gx, gy; fed through update (sign_method other than "phase"),
    # every accumulator of core's state (_AxisState.FIELDS)
    return _AxisState.from_values(row.tolist(), n)


class WalkdirTrace:
    """The stage's run over a grid (:func:`walking_direction_over_grid`): the estimate after each grid sample
    (the current axis ``key`` and its accumulators ``acc`` (n, 6: c2, s2, w, w2, gx, gy; n, len(FIELDS): every field of core's ``_AxisState.FIELDS``
    when fed through ``update``), ``n_used`` (0: no
    estimate)), from ``j_init`` on, and the final state."""

    def __init__(self, j_init, keys, key, acc, n_used, final):
        self.j_init, self.keys = j_init, keys
        self.key, self.acc, self.n_used = key, acc, n_used
        self._final = final
        self._last = len(key) - 1 + j_init
        # the estimate changes only at some samples (an accepted stride, a gap's reset, an axis switch): at()
        # writes into the object only when it differs from what it wrote last
        n = len(key)
        changed = np.ones(n, dtype=bool)
        if n > 1:
            changed[1:] = (key[1:] != key[:-1]) | (n_used[1:] != n_used[:-1]) | (acc[1:] != acc[:-1]).any(axis=1)
        self._version = np.cumsum(changed)
        self._written = None  # (object, version) at() wrote last

    def offset_state(self, j: int):
        """``(axis key, _AxisState or None)`` in force after grid sample ``j`` (None before the first sample
        or with no accepted stride behind the current axis)."""
        i = min(j - self.j_init, len(self.key) - 1)
        if j < self.j_init or i < 0:
            return None, None
        k = int(self.key[i])
        n = int(self.n_used[i])
        return (self.keys[k] if k >= 0 else None), (_axis_state(self.acc[i], n) if n else None)

    def at(self, wd, j: int) -> None:
        """Put into ``wd`` what its ``step_heading``/``applies``/``offset_rad``/``estimate`` read after grid
        sample ``j`` (the current axis and its accumulators); from the last grid sample on, the whole final
        state (:meth:`finish`).  ``wd.n_steps_offset`` (counted by ``step_heading``) is left alone."""
        if j >= self._last:
            self.finish(wd)
            return
        version = int(self._version[j - self.j_init]) if j >= self.j_init else 0
        if self._written is not None and self._written[0] is wd and self._written[1] == version:
            return
        wd.set_axis(*self.offset_state(j))
        self._written = (wd, version)

    def finish(self, wd) -> None:
        """The state ``WalkingDirection.update`` leaves after every grid sample (``n_steps_offset`` kept)."""
        wd.restore_state({name: value() if callable(value) else value for name, value in self._final.items()})
        self._written = None


def walking_direction_over_grid(wd, grid_t, q, acc, fwd_e, fwd_n, step_ticks, axes, j_init: int = 0,
                                axis_keys=None, compiled: bool | None = None) -> WalkdirTrace:
    """``wd.update`` (a :class:`core.pdr.walkdir.WalkingDirection`, reset here) for grid samples ``j_init..``.

    Grid sample ``j`` (``j >= j_init``) is fed as ``StepRelease._walkdir_to`` feeds it: time ``grid_t[j]``, the
    attitude ``q[j]`` (w, x, y, z), the accelerometer reading ``acc[j]`` (m/s^2, device frame), the smoothed
    forward vector ``fwd_e[j - j_init]``, ``fwd_n[j - j_init]``, the step flag ``j in step_ticks`` (a set or
    an array of grid indices) and the smoother's axis ``axes[j - j_init]`` (hashable keys; or, with
    ``axis_keys``, int indices into it).  Returns the :class:`WalkdirTrace`; ``wd`` itself is left reset until
    :meth:`WalkdirTrace.at` or :meth:`WalkdirTrace.finish` writes into it.

    ``compiled`` (default: where numba is installed) runs :func:`walk_kernel`; without it ``wd.update`` itself
    is fed every sample and the estimate recorded after each (the kernel run as plain Python is slower than
    core's update), so the trace is the same either way.  The kernel implements ``sign_method="phase"``
    only, and the gap clock of accepted strides only: any other sign method, ``gap_keeps_turning`` (issue #25),
    ``quadrature_phase`` and ``symmetric_axis_below_ratio`` > 0 are fed through ``wd.update``, whatever
    ``compiled`` says (``phase_axis_below_ratio`` is the kernel's too).
    """
    if compiled is None:
        compiled = HAVE_NUMBA
    if getattr(wd, "sign_method", "phase") != "phase":
        compiled = False  # the kernel mirrors the phase rule only: the skew sign (issue #25) runs core's update
    if getattr(wd, "gap_keeps_turning", False):
        compiled = False  # the kernel's gap clock restarts at accepted strides only: core's update keeps turning
    if getattr(wd, "quadrature_phase", False):
        compiled = False  # the kernel keeps the leaky v_z's covariance: core's update projects the in-phase part out
    if getattr(wd, "symmetric_axis_below_ratio", 0.0) > 0.0:
        compiled = False  # the kernel keeps no stride's samples: core's update finds the symmetric axis (issue #25)
    wd.reset()
    grid_t = np.asarray(grid_t, dtype=np.int64)
    n = len(grid_t) - j_init
    t = np.ascontiguousarray(grid_t[j_init:])
    qq = np.ascontiguousarray(np.asarray(q, dtype=np.float64)[j_init:j_init + n])
    aa = np.ascontiguousarray(np.asarray(acc, dtype=np.float64)[j_init:j_init + n])
    fe = np.ascontiguousarray(np.asarray(fwd_e, dtype=np.float64)[:n])
    fn = np.ascontiguousarray(np.asarray(fwd_n, dtype=np.float64)[:n])
    ticks = np.fromiter(step_ticks, dtype=np.int64) if isinstance(step_ticks, (set, frozenset)) \
        else np.asarray(step_ticks, dtype=np.int64)
    ticks = ticks[(ticks >= j_init) & (ticks < j_init + n)] - j_init
    step = np.zeros(n, dtype=np.bool_)
    step[ticks] = True
    if axis_keys is None:
        axes = list(axes[:n])
        keys = list(dict.fromkeys(axes))  # in order of first appearance
        index = {a: i for i, a in enumerate(keys)}
        ids = np.array(list(map(index.__getitem__, axes)), dtype=np.int64).reshape(n)
    else:
        keys = list(axis_keys)
        ids = np.ascontiguousarray(np.asarray(axes, dtype=np.int64)[:n])
    if not compiled:
        return _fed(wd, t, qq, aa, fe, fn, step, ids, keys, j_init)
    fs = np.zeros(N_F)
    ks = wd.kernel_settings
    fs[[F_DT, F_LEAK, F_ALPHA, F_FORGET, F_MIN_FWD, F_MIN_STRIDE, F_MAX_STRIDE, F_RATE, F_MAX_TURN, F_MIN_TR,
        F_PCA_ANISO, F_MIN_COH, F_MIN_ANISO]] = (
        ks["dt_s"], ks["leak"], ks["mean_alpha"], ks["forget"], wd.min_forward_norm, wd.min_stride_s, wd.max_stride_s,
        wd.grid_rate_hz, wd.max_stride_turn_rad, wd.min_horizontal_std_m_s2 ** 2, wd.pca_min_anisotropy,
        wd.min_coherence, wd.min_anisotropy)
    fs[F_MEAN_U] = math.nan
    fs[F_PHASE_RATIO] = wd.phase_axis_below_ratio
    is_ = np.zeros(N_I, dtype=np.int64)
    is_[I_DELAY_N], is_[I_GAP_NS], is_[I_METHOD] = ks["delay_n"], ks["gap_ns"], _METHODS.index(wd.axis_method)
    is_[I_KEY], is_[I_STEPS], is_[I_EST_KEY] = -1, -1, -1
    nk = max(len(keys), 1)
    ax = np.zeros((nk, 6))
    ax_n = np.zeros(nk, dtype=np.int64)
    ax_order = np.zeros(nk, dtype=np.int64)
    smp = np.zeros((n, 4))
    fifo = np.zeros(n + 1, dtype=np.int64)
    n_rec = len(ticks) + 1
    rec_i = np.zeros((n_rec, 5), dtype=np.int64)
    rec_f = np.full((n_rec, 7), math.nan)
    est = np.zeros(7)
    cur = np.zeros((n, 6))
    cur_n = np.zeros(n, dtype=np.int64)
    cur_key = np.empty(n, dtype=np.int64)
    if n > 0:
        walk_kernel(t, qq, aa, fe, fn, step, ids, fs, is_, ax, ax_n, ax_order, smp, fifo, rec_i, rec_f, est, cur,
                    cur_n, cur_key)
    return WalkdirTrace(j_init, keys, cur_key, cur, cur_n,
                        _final_state(wd, keys, t, step, fs, is_, ax, ax_n, ax_order, smp, fifo, rec_i, rec_f, est))


def _fed(wd, t, q, acc, fe, fn, step, ids, keys, j_init) -> WalkdirTrace:
    """The trace by ``wd.update`` itself, sample by sample (fed as ``StepRelease`` fed it), and its final state."""
    n = len(t)
    cur = np.zeros((n, len(_AxisState.FIELDS)))
    cur_n = np.zeros(n, dtype=np.int64)
    cur_key = np.full(n, -1, dtype=np.int64)
    index = {k: i for i, k in enumerate(keys)}
    upd = wd.update
    tl, ql, al, el, nl, sl, il = t.tolist(), q.tolist(), acc.tolist(), fe.tolist(), fn.tolist(), step.tolist(), \
        ids.tolist()
    for j in range(n):
        a = al[j]
        upd(tl[j], tuple(ql[j]), a[0], a[1], a[2], el[j], nl[j], sl[j], keys[il[j]])
        key = wd.axis_key
        if key is not None:
            cur_key[j] = index[key]
            st = wd.axis_state(key)
            if st is not None and st.n:
                cur[j] = st.values()
                cur_n[j] = st.n
    states = wd.axis_states()  # at() replaces the dict: the final one is kept here (its states no longer change)
    return WalkdirTrace(j_init, keys, cur_key, cur, cur_n, {"_axis_key": wd.axis_key, "_states": states})


def _final_state(wd, keys, t, step, fs, is_, ax, ax_n, ax_order, smp, fifo, rec_i, rec_f, est) -> dict:
    """The attributes of ``wd`` after the updates (callables: built when written)."""

    def key_of(k):
        return keys[int(k)] if k >= 0 else None

    def states():
        live = [k for k in range(len(ax_n)) if ax_n[k] > 0]
        live.sort(key=lambda k: ax_order[k])
        return {key_of(k): _axis_state(ax[k], ax_n[k]) for k in live}

    def buf():
        return deque((int(t[i]), float(smp[i, 0]), float(smp[i, 1]), float(smp[i, 2]), float(smp[i, 3]),
                      bool(step[i])) for i in fifo[is_[I_HEAD]:is_[I_TAIL]].tolist())

    def strides():
        out = deque(maxlen=wd.max_strides_kept)
        first = max(0, int(is_[I_N_REC]) - wd.max_strides_kept) if wd.max_strides_kept > 0 else int(is_[I_N_REC])
        for r in range(first, int(is_[I_N_REC])):
            out.append(_record(rec_i[r], rec_f[r], key_of))
        return out

    def last_estimate():
        if not is_[I_HAS_EST]:
            return None
        return wd.estimate_with(key_of(int(is_[I_EST_KEY])), _axis_state(est[:6], est[6]) if est[6] > 0 else None)

    s = [float(x) for x in fs[F_SUMS:F_SUMS + 14]]
    final = {
        "_mean_u": float(fs[F_MEAN_U]), "_vz": float(fs[F_VZ]), "_buf": buf, "_sums": s,
        "_stride_steps": int(is_[I_STEPS]), "_stride_t0": int(is_[I_T0]),
        "_stride_fwd0": (float(fs[F_FWD0]), float(fs[F_FWD0 + 1])) if is_[I_HAS_FWD0] else None,
        "_stride_skipped": int(is_[I_SKIPPED]), "_axis_key": key_of(is_[I_KEY]), "_states": states,
        "_last_accepted_ns": int(is_[I_LAST_NS]) if is_[I_HAS_LAST] else None,
        "n_gap_resets": int(is_[I_N_GAP]), "last_estimate": last_estimate, "strides": strides,
        "n_strides": int(is_[I_N_STRIDES]), "n_accepted": int(is_[I_N_ACCEPTED]),
        "rejected": {r: int(is_[I_REJ + i]) for i, r in enumerate(REJECT_REASONS)},
        "n_sign_disagreements": int(is_[I_N_SIGN]), "n_nonfinite": int(is_[I_N_NONFINITE]),
    }
    return final


def _record(ri, rf, key_of) -> dict:
    """A stride's record as ``WalkingDirection._close`` makes it (its keys in the order they are set)."""
    out = int(ri[R_OUT])
    reason = "" if out == 0 else REJECT_REASONS[out - 1]
    rec = {"t_ns": int(ri[R_T]), "accepted": False, "reason": "", "axis_offset_rad": math.nan,
           "offset_rad": math.nan, "anisotropy": math.nan, "corr": math.nan, "sign": 0}
    if reason in ("duration", "vertical_axis", "samples"):
        pass
    else:
        rec["turn_rad"] = float(rf[R_TURN])
        if reason not in ("turning", "still"):
            rec["anisotropy"] = float(rf[R_ANISO])
            rec["coherence"] = float(rf[R_COHERENCE])
            rec["method"] = _METHODS[int(ri[R_METHOD])]
            if reason != "incoherent":
                rec["axis_anisotropy"] = float(rf[R_AXIS_ANISO])
                if reason != "isotropic":
                    rec["axis_offset_rad"] = float(rf[R_AXIS_OFFSET])
                    rec["corr"] = float(rf[R_CORR])
                    rec["axis"] = key_of(int(ri[R_AXIS]))
                    rec["sign"] = int(ri[R_SIGN])
                    rec["offset_rad"] = float(rf[R_OFFSET])
                    rec["accepted"] = True
    if reason:
        rec["reason"] = reason
    return rec
