"""Step detection and the speed window over the grid arrays: a second implementation of
:class:`core.pdr.steps.StepDetector` (Tian et al. 2014, eqs. 2-3) and of
:class:`core.pdr.velocity.SpeedFeatureWindow` (Kubrak's eq. 1 regressors).

Both are compiled loops over the grid (the Butterworth low-pass is the
recursion ``lfilter`` runs, direct form II transposed, started at the steady
state of the first sample; the peak test, thresholds and bout bookkeeping
depend on the previous samples).  They follow the reference's order of
operations, so every step is the same.  The step detector takes a carry
mode's gates (:class:`core.pdr.steps.StepGates`: the stride comb, the cadence
and echo gates, the mode's ``A_th`` and gravity time constant) with the step
period the carry detector gives it at every grid sample.  Deliberately a
second implementation (issue #13 item 3).
"""

from __future__ import annotations

import math

import numpy as np

from core.dsp import butter2_group_delay_s, butter2_lowpass
from desktop.fast.jit import kernel


@kernel
def biquad_reset(c, x0):
    """(z1, z2) of the steady state of a constant input ``x0`` (``lfilter_zi * x0``); c = (b0, b1, b2, a1, a2)."""
    gain = (c[0] + c[1] + c[2]) / (1.0 + c[3] + c[4])
    y0 = gain * x0
    return y0 - c[0] * x0, c[2] * x0 - c[4] * y0


@kernel
def detect(t_ns, x, restart, c, alpha_g, min_peak, max_dt_ns, delay_ns, require_valley, g0,
           comb_lag, gate_dt_ns, min_raw_range, range_back, hist, ev_tick, ev_t, ev_f, period, rescue_h, rescue_lo,
           rescue_hi, pos_lo, pos_hi, flush):
    """The peaks of eq. 3 on the grid, with a carry mode's gates (:class:`core.pdr.steps.StepGates`); returns how
    many.

    Per grid sample, from the step period the detector holds there: ``comb_lag`` the stride comb's delay in
    samples (0: no comb); ``gate_dt_ns`` the time threshold of eq. 3 with the cadence gate; ``range_back`` how many
    raw samples the echo gate looks back (``min_raw_range`` <= 0: no echo gate).  ``hist``: the comb's ring of raw
    norms (its length is the detector's).  ``ev_tick[k]``: the grid sample at which step ``k`` is found; ``ev_t[k]``
    its time (the peak less the low-pass delay); ``ev_f[k]``: A_max, A_min, variance, duration (nan: first of a
    bout), gravity.  ``period``: the step period per grid sample (nan: unknown); ``rescue_h`` (0: off),
    ``rescue_lo``, ``rescue_hi``, ``pos_lo``, ``pos_hi``: the weak-step rescue's height, interval (periods) and
    position (:class:`core.pdr.steps.StepGates`).  ``flush``: the end of data
    (:meth:`core.pdr.steps.StepDetector.flush`, ``Pipeline(flush_at_end=True)``): after the last sample, the step
    waiting behind a rescued one and a filtered norm still rising at the last sample (the peak tests with the last
    sample's gates), found at grid sample ``len(t_ns)``.
    """
    n_hist = len(hist)
    hist_k = 0
    hist_n = 0
    n_ev = 0
    n_grid = 0
    gravity = g0
    have1 = False
    have2 = False
    y1 = 0.0
    y2 = 0.0
    t1 = 0
    has_last = False
    last = 0
    armed = True
    seg_min = math.inf
    seg_sum = 0.0
    seg_sum2 = 0.0
    seg_n = 0
    z1 = 0.0
    z2 = 0.0
    # the weak-step rescue: the weak peak held since the last step, the step given out a sample late
    has_weak = False
    w_t = 0
    w_y = w_g = w_min = w_sum = w_sum2 = 0.0
    w_n = 0
    after_min = math.inf
    has_stash = False
    s_t = 0
    s_f0 = s_f1 = s_f2 = s_f3 = s_f4 = 0.0
    b0, b1, b2, a1, a2 = c[0], c[1], c[2], c[3], c[4]
    n_t = len(t_ns)
    for k in range(n_t + 1 if flush and n_t else n_t):
        end = k == n_t  # the flush: no sample, the tests on the last one (its gates: kk)
        kk = n_t - 1 if end else k
        tk = t_ns[kk]
        norm = x[kk]
        if not end and restart[k] and n_grid:  # restart_bout
            have1 = have2 = False
            has_last = False
            armed = True
            seg_min = math.inf
            seg_sum = seg_sum2 = 0.0
            seg_n = 0
            hist_n = 0
            has_weak = False
            after_min = math.inf
        if has_stash:  # the step found with a rescued one, given out at this sample
            ev_tick[n_ev] = k
            ev_t[n_ev] = s_t
            ev_f[n_ev, 0], ev_f[n_ev, 1], ev_f[n_ev, 2], ev_f[n_ev, 3], ev_f[n_ev, 4] = s_f0, s_f1, s_f2, s_f3, s_f4
            n_ev += 1
            has_stash = False
        if end:
            g = gravity
            y = -math.inf  # the last sample, still rising, is the data's maximum
        else:
            if not have1:
                z1, z2 = biquad_reset(c, norm)
                if n_grid == 0:
                    gravity = norm
            n_grid += 1
            gravity = gravity + alpha_g * (norm - gravity)
            g = gravity
            hist[hist_k] = norm  # the stride comb's delay line (core.pdr.steps.StepDetector._comb)
            written = hist_k
            hist_k = (hist_k + 1) % n_hist
            if hist_n < n_hist:
                hist_n += 1
            lag = comb_lag[k]
            xin = norm
            if lag >= 1 and lag < min(n_hist, hist_n):
                xin = 0.5 * (norm + hist[(written - lag) % n_hist])
            y = b0 * xin + z1  # the biquad, direct form II transposed
            z1 = b1 * xin - a1 * y + z2
            z2 = b2 * xin - a2 * y
        if have1 and have2 and y1 > y2 and y1 >= y:  # a local maximum at the previous sample
            t_peak = t1
            since = t_peak - last
            pk = period[kk]
            timed = ((not has_last) or since > gate_dt_ns[kk]) and armed  # eq. 3, the time threshold; the valley
            echo = True
            if min_raw_range > 0.0:  # the echo gate: the raw norm's range over the last half period
                back = min(n_hist, hist_n, range_back[kk])
                rng = 0.0
                if back >= 2:
                    lo_v = math.inf
                    hi_v = -math.inf
                    for i in range(back):
                        v = hist[(hist_k - 1 - i) % n_hist]
                        lo_v = min(lo_v, v)
                        hi_v = max(hi_v, v)
                    rng = hi_v - lo_v
                echo = rng >= min_raw_range
            if y1 - g > min_peak[kk] and timed and echo:  # eq. 3 (A_th per sample: relative_peak_height)
                rescue = (has_weak and pk > 0.0 and rescue_lo * pk * 1e9 <= since <= rescue_hi * pk * 1e9
                          and pos_lo * since <= w_t - last <= pos_hi * since and t_peak - w_t > gate_dt_ns[kk])
                if rescue:  # the weak step now, this one at the next sample
                    mean = w_sum / w_n if w_n else w_y
                    var = max(w_sum2 / w_n - mean * mean, 0.0) if w_n else 0.0
                    ev_tick[n_ev] = k
                    ev_t[n_ev] = w_t - delay_ns
                    ev_f[n_ev, 0], ev_f[n_ev, 1], ev_f[n_ev, 2] = w_y, w_min if w_min < math.inf else w_y, var
                    ev_f[n_ev, 3], ev_f[n_ev, 4] = (w_t - last) * 1e-9, w_g
                    n_ev += 1
                    n2 = seg_n - w_n
                    mean = (seg_sum - w_sum) / n2 if n2 else y1
                    var = max((seg_sum2 - w_sum2) / n2 - mean * mean, 0.0) if n2 else 0.0
                    has_stash = True
                    s_t = t_peak - delay_ns
                    s_f0, s_f1, s_f2 = y1, after_min if after_min < math.inf else y1, var
                    s_f3, s_f4 = (t_peak - w_t) * 1e-9, g
                else:
                    mean = seg_sum / seg_n if seg_n else y1
                    var = max(seg_sum2 / seg_n - mean * mean, 0.0) if seg_n else 0.0
                    acc_min = seg_min if seg_min < math.inf else y1
                    duration = since * 1e-9 if has_last and since <= max_dt_ns else math.nan
                    ev_tick[n_ev] = k
                    ev_t[n_ev] = t_peak - delay_ns
                    ev_f[n_ev, 0], ev_f[n_ev, 1], ev_f[n_ev, 2] = y1, acc_min, var
                    ev_f[n_ev, 3], ev_f[n_ev, 4] = duration, g
                    n_ev += 1
                last = t_peak
                has_last = True
                armed = not require_valley
                seg_min = math.inf
                seg_sum = seg_sum2 = 0.0
                seg_n = 0
                has_weak = False
                after_min = math.inf
            elif (rescue_h > 0.0 and has_last and timed and echo and pk > 0.0 and y1 - g > rescue_h
                  and ((not has_weak) or y1 - g > w_y - w_g)):  # a weak peak only the amplitude refused: held
                has_weak = True
                w_t, w_y, w_g, w_min, w_sum, w_sum2, w_n = t_peak, y1, g, seg_min, seg_sum, seg_sum2, seg_n
                after_min = math.inf
        if end:
            if has_stash:  # the step found with the flush's rescued one
                ev_tick[n_ev] = k
                ev_t[n_ev] = s_t
                ev_f[n_ev, 0], ev_f[n_ev, 1], ev_f[n_ev, 2], ev_f[n_ev, 3] = s_f0, s_f1, s_f2, s_f3
                ev_f[n_ev, 4] = s_f4
                n_ev += 1
                has_stash = False
            break
        if y < g:
            armed = True
        if has_last and tk - last > max_dt_ns:  # a pause
            has_last = False
            seg_min = math.inf
            seg_sum = seg_sum2 = 0.0
            seg_n = 0
            has_weak = False
            after_min = math.inf
        if y < seg_min:
            seg_min = y
        if y < after_min:
            after_min = y
        seg_sum += y
        seg_sum2 += y * y
        seg_n += 1
        y2, have2 = y1, have1
        y1, have1, t1 = y, True, tk
    return n_ev


def detect_steps(detector, t_ns, x, restart, gates=None, step_period_s=None, flush=False, gait_std_m_s2=None):
    """StepEvent fields of every step the reference ``detector`` (its settings) finds on the grid (``flush``: and
    those its :meth:`core.pdr.steps.StepDetector.flush` gives at the end, found at grid sample ``len(t_ns)``).

    ``gates``: the carry mode's :class:`core.pdr.steps.StepGates` in force (default: the detector's own);
    ``step_period_s``: the step period the detector is given at each grid sample (the carry detector's; default:
    none, nan), which the stride comb, the cadence gate and the echo gate use; ``gait_std_m_s2``: the carry
    detector's gait amplitude at each grid sample (nan: unknown), for ``gates.relative_peak_height``.
    """
    from core.conventions import STANDARD_GRAVITY_M_S2
    from core.pdr.steps import MAX_COMB_PERIOD_S

    gates = detector.gates if gates is None else gates
    rate = detector.grid_rate_hz
    b, a = butter2_lowpass(detector.cutoff_hz, rate)
    c = np.array([b[0] / a[0], b[1] / a[0], b[2] / a[0], a[1] / a[0], a[2] / a[0]])
    tau = detector.gravity_time_constant_s if gates.gravity_time_constant_s is None else gates.gravity_time_constant_s
    alpha_g = 1.0 - math.exp(-1.0 / (rate * tau))
    a_th = detector.min_peak_height_m_s2 if gates.min_peak_height_m_s2 is None else gates.min_peak_height_m_s2
    n = len(t_ns)
    period = np.full(n, np.nan) if step_period_s is None else np.asarray(step_period_s, dtype=float)
    min_peak = np.full(n, float(a_th))
    if gates.relative_peak_height > 0.0 and gait_std_m_s2 is not None:  # the reference's min(A_th, rel * std)
        amp = np.asarray(gait_std_m_s2, dtype=float)
        rel = np.minimum(a_th, gates.relative_peak_height * np.where(amp > 0.0, amp, np.inf))
        min_peak = np.where(amp > 0.0, rel, min_peak)
    known = period > 0.0
    p = np.where(known, period, 0.0)
    n_hist = int(MAX_COMB_PERIOD_S * rate) + 2
    # the reference's int(round(period * rate)), int(frac * period * 1e9), int(0.5 * period * rate), per sample
    comb_lag = np.where(known, np.round(p * rate), 0.0).astype(np.int64) if gates.stride_comb \
        else np.zeros(n, np.int64)
    min_dt = int(detector.min_step_interval_s * 1e9)
    frac = gates.min_interval_period_frac
    gate_dt = np.full(n, min_dt, dtype=np.int64)
    if frac > 0.0:
        gate_dt = np.where(known, np.maximum(min_dt, np.trunc(frac * p * 1e9).astype(np.int64)), min_dt)
    delay_samples = int(round(butter2_group_delay_s(detector.cutoff_hz) * rate))
    range_back = np.where(known, np.trunc(0.5 * p * rate).astype(np.int64) + delay_samples + 2, n_hist)
    ev_tick = np.empty(n // 2 + 3, dtype=np.int64)
    ev_t = np.empty(len(ev_tick), dtype=np.int64)
    ev_f = np.empty((len(ev_tick), 5))
    k = detect(t_ns, x, restart, c, alpha_g, np.ascontiguousarray(min_peak), int(detector.max_step_interval_s * 1e9),
               int(round(butter2_group_delay_s(detector.cutoff_hz) * 1e9)), detector.require_valley,
               STANDARD_GRAVITY_M_S2, np.ascontiguousarray(comb_lag), np.ascontiguousarray(gate_dt),
               float(gates.min_raw_range_m_s2), np.ascontiguousarray(range_back.astype(np.int64)), np.zeros(n_hist),
               ev_tick, ev_t, ev_f, np.ascontiguousarray(period), float(gates.rescue_peak_height_m_s2),
               float(gates.rescue_interval_periods[0]), float(gates.rescue_interval_periods[1]),
               float(gates.rescue_position_frac[0]), float(gates.rescue_position_frac[1]), bool(flush))
    return ev_tick[:k].copy(), ev_t[:k].copy(), ev_f[:k].copy()


@kernel
def speed_features(t_ns, x, restart, c, window_ns, full_ns, min_hyst, at_tick, out):
    """MEAN, FREQ, STD of |a| over the trailing window at the grid samples ``at_tick`` (sorted).

    The window restarts with the grid (the pipeline resets it there); crossings of the low-passed norm
    through the hysteresis band above the window mean are counted as the reference counts them.
    """
    n = len(t_ns)
    crossings = np.empty(n + 1, dtype=np.int64)
    c_lo = 0
    c_hi = 0
    lo = 0
    s1 = 0.0
    s2 = 0.0
    started = False
    below = False
    has_prev = False
    prev_t = 0
    prev_y = 0.0
    z1 = 0.0
    z2 = 0.0
    b0, b1, b2, a1, a2 = c[0], c[1], c[2], c[3], c[4]
    m = 0
    for k in range(n):
        tk = t_ns[k]
        v = x[k]
        if restart[k] and k:  # reset()
            lo = k
            s1 = s2 = 0.0
            started = below = has_prev = False
            c_lo = c_hi = 0
        if not started:
            z1, z2 = biquad_reset(c, v)
            started = True
        s1 += v
        s2 += v * v
        limit = tk - window_ns
        while t_ns[lo] <= limit:
            old = x[lo]
            lo += 1
            s1 -= old
            s2 -= old * old
        nw = k + 1 - lo
        mean = s1 / nw
        sd = math.sqrt(max(s2 / nw - mean * mean, 0.0))
        h = max(0.25 * sd, min_hyst)
        yl = b0 * v + z1
        z1 = b1 * v - a1 * yl + z2
        z2 = b2 * v - a2 * yl
        y = yl - mean
        if y < -h:
            below = True
        elif below and y > h and has_prev:
            frac = (h - prev_y) / (y - prev_y) if y != prev_y else 1.0
            crossings[c_hi] = prev_t + int(min(max(frac, 0.0), 1.0) * (tk - prev_t))
            c_hi += 1
            below = False
        prev_t, prev_y, has_prev = tk, y, True
        while c_hi > c_lo and crossings[c_lo] <= limit:
            c_lo += 1
        while m < len(at_tick) and at_tick[m] == k:
            if nw > 1 and t_ns[k] - t_ns[lo] >= full_ns:
                mean_ = s1 / nw
                sd_ = math.sqrt(max(s2 / nw - mean_ * mean_, 0.0))
                nc = c_hi - c_lo
                if nc >= 2 and crossings[c_hi - 1] > crossings[c_lo]:
                    freq = (nc - 1) / ((crossings[c_hi - 1] - crossings[c_lo]) * 1e-9)
                else:
                    freq = 0.0
                out[m, 0], out[m, 1], out[m, 2] = mean_, freq, sd_
            else:
                out[m, 0] = out[m, 1] = out[m, 2] = math.nan
            m += 1


def speed_at(window, t_ns, x, restart, at_tick):
    """The reference ``window``'s (its settings) features at the grid samples ``at_tick`` (sorted), (m, 3)."""
    b, a = window.lowpass_ba
    c = np.array([b[0] / a[0], b[1] / a[0], b[2] / a[0], a[1] / a[0], a[2] / a[0]])
    window_ns = int(window.window_s * 1e9)
    out = np.empty((len(at_tick), 3))
    speed_features(t_ns, x, restart, c, window_ns, window_ns - int(2e9 / window.grid_rate_hz),
                   window.min_hysteresis_m_s2, np.ascontiguousarray(at_tick, dtype=np.int64), out)
    return out
