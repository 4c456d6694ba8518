"""How the phone is carried (issue #17): carry-mode detection from the signals alone, causal and cheap.

:class:`CarryModeDetector` is fed every sample of the pipeline's uniform grid
(50 Hz) with the acceleration vector in the device frame (gravity included)
and, when the recording has one, the gyroscope vector.  It keeps the last
``window_s`` seconds in ring buffers (O(1) per sample) and every ``hop_s``
seconds computes a handful of features over the window with numpy (a few
hundred microseconds once per hop: a few microseconds per sample).  Every mode
must be recognisable from the accelerometer alone (the Oxford traces have no
gyroscope); the gyroscope only sharpens the decision between a swinging hand
and a waving hand.

Features and the physics they come from
=======================================

``gravity_b`` (unit vector, device frame)
    The window mean of the specific force: while walking, the body's
    accelerations average out over a few strides and what is left is gravity
    (the phone reads ``+g`` up).  Its direction is where the phone "looks":
    a phone read or texted in front of the chest lies screen up, tilted
    towards the face (``+z`` large, some ``+y``); a phone at the ear stands
    upright, its top up (``+y`` large, ``z`` small); a phone in a trouser
    pocket stands along the thigh (``|y|`` large, top up or down).
``tilt_rms_rad``
    RMS angle between the specific force smoothed over ``tilt_smooth_s``
    (a 0.2 s mean: the impacts of the heel strike are removed, the swing of a
    limb is kept) and ``gravity_b``.  A phone coupled to the trunk (hand in
    front of the chest, ear, bag) tilts by a few degrees with the trunk's
    sway; a phone on a limb tilts with the limb, which swings at the stride
    frequency: the thigh by about +-20-30 deg, a hanging arm by +-20-45 deg
    at the hand.  A pendulum point below the arm's centre of percussion also
    feels a tangential specific force, so the hand sees the largest apparent
    tilt.
``coherence``
    ``|mean(a)| / mean(|a|)``: 1 when the specific force keeps one
    direction, lower when it turns (the swinging arm's centripetal and
    tangential accelerations rotate it through a large angle every stride).
``periodicity``, ``step_period_s``, ``stride_share``
    Normalised autocorrelation of the acceleration norm at the stride lag
    (the strongest one between ``min_stride_s`` and ``max_stride_s``) and at
    half of it (the step lag).  Gait is periodic: both are high while
    walking; a table, a phone held while standing or a vehicle's vibration
    have no gait periodicity.  ``stride_share = R(stride) - R(step)``: a
    phone on the trunk sees both feet alike (the norm repeats every step,
    ``R(step) ~ R(stride)``); a phone on a limb sees the two half-strides
    differently (the near leg's impact is stronger in a pocket; the arm is
    forward on one step and back on the next), so the norm repeats every
    stride only.
``tilt_stride_corr``
    Autocorrelation of the tilt at the stride lag: a limb swings once per
    stride (a periodic tilt), the trunk's sway is small and irregular.
``acc_std_m_s2``
    Standard deviation of the norm: the energy of the gait.  Under
    ``min_walk_std_m_s2`` nobody is walking (a phone on a table reads
    noise of ~0.02 m/s^2, one held while standing ~0.1-0.3).
``recent_std_m_s2``
    The same over the window's last ``hold_recent_s``: whether the motion goes
    on at the window's end (a walk being held through a turn) or has stopped.
``horizontal_ratio``
    sqrt(horizontal / vertical variance) of the specific force about
    ``gravity_b``: on the trunk the gait's acceleration is mostly vertical
    (the body's centre of mass rises and falls every step); on a swinging
    arm or leg the limb's tangential and centripetal accelerations add a
    large horizontal part.
``gyro_rms_rad_s``, ``gyro_axis_share``, ``gyro_periodicity`` (gyroscope only)
    A swinging arm turns the phone fast (2-6 rad/s) about one axis (the
    shoulder's pivot), periodically at the stride frequency: most of the
    rotation's variance is on one axis and its autocorrelation at the stride
    lag is high.  Waving the phone to calibrate the compass is as fast but
    irregular and about all three axes: ``rotation_periodic`` is False then,
    and the pipeline's rotation gate keeps those peaks out even in the
    swinging mode.  ``gyro_skew``: the ``|skewness|`` of the rate about the
    main axis; a thigh's rotation is skewed (slow extension in stance, quick
    flexion in swing), an arm's pendulum swing is not (issue #25).  Periodicity decides, not the axis (issue #25): a real
    hand twists the phone about the forearm as it swings, which spreads the
    rotation over two axes (main-axis share 0.5-0.7) but keeps it periodic at
    the stride; a rotation periodic at the stride while the norm is periodic
    is a gait's, whatever its axes.
    The swing per stride (:meth:`CarryModeDetector.stride_swing_deg`, derived from these): a phone at the ear
    turns with the head by a few degrees per stride, a swung hand by tens (``ear_max_swing_deg``, 20 by default).

Decision
========
Each mode gets a score in [0, 1] from soft thresholds (logistic functions of
the features, settings below; a phone read in the hand that neither tilts nor swings is no limb's, whatever the
norm's stride share: ``hand_limb_min_tilt_rad``, ``hand_limb_max_swing_deg``); the raw decision of a hop is the best score,
its confidence the best score's share of the total.  Hysteresis: a new mode
replaces the current one only after it has been the raw decision for
``switch_s`` seconds without interruption (``still`` <-> walking after
``switch_still_s``); the first full window decides the initial mode at once.
Every change is logged as ``(t_ns, from, to, confidence)``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from core.conventions import (CARRY_BAG, CARRY_EAR, CARRY_HANDHELD, CARRY_MODES, CARRY_POCKET, CARRY_STILL,
                              CARRY_SWINGING)


class CarryChange(NamedTuple):
    """One entry of :attr:`CarryModeDetector.changes`: the decided mode changed at a grid sample."""

    t_ns: int  #: the grid sample whose decision changed the mode
    from_mode: str  #: the mode in force before (one of core.conventions.CARRY_MODES)
    to_mode: str  #: the mode in force from ``t_ns`` on
    confidence: float  #: the new mode's confidence 0..1 at the change


def _optional_angle(name: str, value, unit: str) -> float | None:
    """An optional angle setting: None (the rule off) or a finite angle > 0, as a float; else ValueError."""
    if value is None:
        return None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be None or a finite angle > 0 ({unit}), got {value!r}")
    return float(value)


def _sig(x: float, x0: float, width: float) -> float:
    """Logistic membership: 0.5 at ``x0``, 0.73 at ``x0 + width``."""
    z = (x - x0) / width
    if z > 30.0:
        return 1.0
    if z < -30.0:
        return 0.0
    return 1.0 / (1.0 + math.exp(-z))


def rotation_skew(p: np.ndarray) -> float:
    """``|skewness|`` of the rotation rate about its main axis ``p`` (zero-mean, rad/s): 0 for a pendulum's
    symmetric swing (an arm), large for the thigh's slow extension in stance and quick flexion in swing."""
    m2 = float(np.add.reduce(p * p)) / len(p)
    if m2 < 1e-12:
        return 0.0
    return abs(float(np.add.reduce(p * p * p)) / len(p)) / (m2 * math.sqrt(m2))


def _hand(f: dict, screen_up_z: float) -> float:
    """Soft evidence (0..1) that the phone is read in the hand (features ``f``): screen up (``screen_up_z``), pitched
    towards the face (gravity in the device's y-z plane, y not down)."""
    return (_sig(f["gravity_z"], screen_up_z, 0.06) * (1.0 - _sig(abs(f["gravity_x"]), 0.5, 0.06))
            * _sig(f["gravity_y"], -0.3, 0.06))


class CarryModeDetector:
    """Carry mode from the acceleration (and gyroscope) on the pipeline's grid; causal, O(1) per sample.

    Parameters
    ----------
    grid_rate_hz : float
        Rate of the samples fed to :meth:`update_grid` (Hz).
    window_s : float
        Length of the feature window (s): two strides of a slow walk.
    hop_s : float
        The features and the raw decision are computed every ``hop_s`` seconds (s).
    tilt_smooth_s : float
        Mean over which the specific force's direction is smoothed for ``tilt_rms_rad`` (s).
    min_stride_s, max_stride_s : float
        Range of the stride period searched in the autocorrelation (s); a
        walking cadence of 0.8-2.5 steps/s is a stride of 0.8-2.5 s (issue #25: a slow, gentle walk at
        0.8-1.2 steps/s is a stride of 1.7-2.5 s).  ``max_stride_s`` is the range of the ``window_s`` window and of a brisk norm's long one (``slow_window_max_std_m_s2``).
    slow_window_s, slow_window_stride_s, slow_window_max_std_m_s2, slow_window_max_stride_s : float
        Issue #25 section 2: a walk at 0.8-0.95 steps/s (a stride of 2.1-2.5 s) fills most of the ``window_s``
        window, its autocorrelation at the stride lag has 1.5-1.9 s of overlap and is noisy, and the decision flapped
        between walking and "not walking" (the hysteresis then never left "not walking": the simulator's gentle swing
        and pocket at 0.8 steps/s 0 and 8 of 22 steps).  The ring holds ``slow_window_s`` (s; two strides at
        0.8 steps/s); a hop whose ``window_s`` features find a stride of ``slow_window_stride_s`` (s) or longer
        computes them again over the long window and takes those when they find such a stride too (a slow walk on
        the trunk's window at three steps' lag, the long one at one stride, keeps the short window's: the tuning clip
        50_hand_slow), and only while the norm moves less than ``slow_window_max_std_m_s2`` (m/s^2; the slow band's
        ``slow_off_std_m_s2``), and a window whose norm moves less than that searches the stride up to
        ``slow_window_max_stride_s`` (s; a 2.5-s stride on ``max_stride_s``, the range's last lag, is no local
        maximum).  A brisk walk's 4-s window can peak at two or three steps' lag too (the Microsoft tuning traces'
        first seconds, 1.5-3 m/s^2): that range and the long window for every amplitude called three hand-held traces
        a pocket for 4-10 s (their landmark errors 5.2/1.8/4.0 -> 4.4/1.5/5.4 m); the ``window_s`` window's own range
        stays ``max_stride_s`` (:meth:`lag_hi`).  The FFT length is the same (512 at 50 Hz); the cost doubles only on
        the hops of a very slow walk.  ``slow_window_s=0``: off.  The ninth session's window (taken on every such hop)
        was off in review: on the TUNING split's hand-held walks (IPIN, Microsoft), where nobody walks at 0.8-0.95
        steps/s, it was taken on 265 of 6300 hops (4 %: stops and turns, where the 4-s window found a stride of 2.1 s
        or more), without a gain there; the REPORT split (seen after the merge) showed what that can cost: IPIN T05r04
        147 -> 145 steps, its landmark error 2.24 -> 2.73 m.  Hence the two gates below; **on by default** with them.
    slow_window_min_periodicity, slow_window_while_still : float, bool
        The long window decides a hop only when its gait is periodic at both legs' lags (:meth:`gait_periodicity`)
        at least ``slow_window_min_periodicity`` (the gentle gait's 0.6) and, with ``slow_window_while_still``, only
        while the mode in force is "not walking" (it starts a very slow walk; once walking, the ``window_s`` window's
        hold keeps it: :meth:`slow_window_open`).  TUNING (IPIN, Microsoft, IPOL, the 28 real walks): of 16493 hops
        none takes it (the 203 hops where both windows find a very slow stride, stops and turns, read at most 0.36
        at both legs' lags), every step and carry time identical to the window off.  Simulator
        (16 m, seed 5, 0.8-0.95 steps/s, six placements and bounces 0.5-1, 72 walks): 1567 -> 1811 of 2016 steps,
        "not walking" 35 -> 20 % of the walk, the long window on 498 of 4302 hops (the ungated window: 1805, on 3074).
    slow_stride_s, slow_stride_margin : float
        A stride longer than ``slow_stride_s`` (s; a cadence under 1.25 steps/s) is taken only when the
        autocorrelation has no peak within ``slow_stride_margin`` of its best at the shorter lags: at a
        normal cadence the autocorrelation over a 4 s window at two strides' lag is as high as at one,
        and noisier.
    slow_stride_edge : bool
        On by default (issue #25 section 2).  When the autocorrelation has no peak within the normal cadence's range
        (up to ``slow_stride_s``) and that range is taken (``slow_stride_margin``), the stride is the peak that
        straddles its edge (the lags past it while the autocorrelation still rises, up to its first fall): a walk at
        about 1.2 steps/s has its stride (1.6-1.75 s) there, and the edge, no peak, gave the norm's autocorrelation on
        the way up (0.2-0.3) at both lags, "not walking".  Simulator (a gently swung hand at 1.2 steps/s,
        ``swing_scale`` 1-1.5, bounce 0.5-1, seeds 7 and 11, 30 m): 243 of 624 steps before ("not walking" 97 % of
        the walk at bounce 0.5-0.75), 589 after (with :data:`core.pdr.steps.GENTLE_SWING_GATES`).  TUNING: the 28 real walks, IPIN (16), Microsoft (18), IPOL (58) and the
        simulator's carry seeds 0-9 count the same steps (benchmarks/discussion.md).  A first version that extended
        the range whenever it rose through its edge (with a peak inside or not) moved the tuning clip Tclack88
        50_hand_slow 50 -> 51 of 50.  False: as before.
    half_stride_ratio : float
        A slow stride's lag (one found past ``slow_stride_s``) is taken for two strides when the autocorrelation
        has a local maximum within 2 samples of half of it at least this fraction of its value there (0: off):
        over a 4-s window the unbiased autocorrelation at two strides' lag (2.1 s: 1.9 s of overlap) is noisy and
        often higher than at one.  TUNING (yh570/sensibility_testbed): the step period read two steps (2x) on
        3-11 % of the hops of its long pocket, coat and hand walks, 0.4-4.3 % with it; the 26 counted clips
        1.50 -> 1.49 % (one two-step gap rescued); most missed steps there sit in gaps the period already judges
        right (benchmarks/REAL_WALKS_RESULTS.md, "The carry detector's step period").
    min_walk_std_m_s2 : float
        Norm standard deviation from which a periodic norm is a normal walk (m/s^2).
    min_periodicity : float
        Autocorrelation at the stride or step lag below which there is no gait.
    gentle_min_std_m_s2, gentle_min_periodicity : float
        A gentle walk (issue #25: a slow walk with the phone held still, 0.5-1 m/s^2 of user acceleration)
        moves the norm by less than ``min_walk_std_m_s2`` but is as periodic as any walk: a norm whose
        standard deviation is above ``gentle_min_std_m_s2`` (m/s^2; a phone on a table reads ~0.02, one
        held while standing under 0.1 by tremor) and whose autocorrelation at both the step and the stride lag
        (both legs) is above ``gentle_min_periodicity`` is walking too: periodicity decides, not amplitude.
    slow_min_std_m_s2, slow_min_periodicity, slow_hold : float, float, bool
        A slow walk whose norm moves more than a standing phone's but less than ``min_walk_std_m_s2`` (issue #25
        part 2: the tuning clip Tclack88 50_hand_slow, 1.1 steps/s in the hand, accelerometer only: standard
        deviation 0.5-0.8 m/s^2, autocorrelation at the step and at the stride 0.4-0.7, "still" for 36 of its 44 s
        before) is walking when the norm's standard deviation is above ``slow_min_std_m_s2`` (m/s^2; a phone held
        while standing moves it by 0.1-0.3) and its periodicity at both legs' lags above ``slow_min_periodicity``:
        the more the norm moves, the less periodicity it takes; "still" needs a low amplitude AND no gait
        periodicity.  Only for a slow walk's stride (``slow_stride_s`` or longer, a cadence under 1.25 steps/s):
        for every stride, the gentle gates below moved the CI guard's IPIN report fit 1.45 -> 1.65 m and the IPIN
        TUNING landmark median 2.29 -> 2.42 m.  ``slow_hold``: once walking (the hold of ``hold_periodicity``, below), the slow band needs
        only the norm's periodicity at either lag above ``hold_periodicity`` (a 4-s window holds barely two strides
        of such a walk: its stride-lag autocorrelation dips to 0.15-0.3 while the step-lag one stays at 0.5).
        ``slow_min_periodicity=inf, slow_hold=False`` turn it off.
    gentle_max_std_m_s2, slow_max_std_m_s2, slow_off_std_m_s2 : float
        While the norm is periodic at both legs' lags (``gentle_min_periodicity``, or at a slow stride
        ``slow_min_periodicity`` from ``slow_min_std_m_s2``) with a standard deviation under ``gentle_max_std_m_s2``
        (m/s^2; at a slow stride ``slow_max_std_m_s2``), :attr:`gentle` is True (off again from ``min_walk_std_m_s2``,
        at a slow stride ``slow_off_std_m_s2``, or when either lag's autocorrelation falls under
        ``min_periodicity``: a band, so that it does not flap): the pipeline then counts the steps of a mode with
        the hand-held gates with the gentle gait's step detector (:data:`core.pdr.steps.GENTLE_GATES`: a low
        ``A_th`` behind the cadence gate).  Issue #25 part 2: a slow stride's band reaches 1.0 / 1.2 m/s^2: the slow
        clip's peaks rise 0.2-0.7 m/s^2 above ``g``, under the hand-held ``A_th`` half the time (30 of 50 steps
        with it, 50 with the gentle gates); every other TUNING real walk (25 counted clips, 2 GPS walks) counts the
        same (for every stride, not only a slow one: yh570 hand_1_28_21_35 364 -> 363 of 372).
    step_antiphase : float
        A slow walk on the trunk repeats its norm every step, and a step of 0.8-1.25 s lies inside the
        stride range: when the autocorrelation at half the lag found is below this (the half lag is in
        anti-phase: the lag is one period of the norm) and the phone is on the trunk (``trunk_max_tilt_rad``)
        or the gyroscope's rotation, which a walker sways once per stride, is in anti-phase at that lag too,
        the lag is the step and the stride twice it.
    trunk_min_periodicity : float
        The norm's autocorrelation at the lag found from which a norm in anti-phase at half of it, on a phone that
        hardly tilts (``trunk_max_tilt_rad``), is a trunk's step (issue #25 part 2: 0.4; it was
        ``gentle_min_periodicity``, 0.6, and the slow clip's 0.4-0.6 made its step a stride and its half-step a step).
    trunk_max_tilt_rad : float
        ``tilt_rms_rad`` under which a norm repeating at the lag found (in anti-phase at half of it) is a trunk's
        step, not a limb's stride (rad; issue #25: at 0.8-1.2 steps/s the simulator's bag and ear tilt by
        0.03-0.09 rad, a limb that repeats only every stride swings by 0.25-0.4, a thigh by 0.16-0.2 but its
        norm is not in anti-phase at the step).  The step/stride ambiguity of a gentle trunk walk: its norm
        at 1 step/s looks like a limb's at 2 steps/s; the tilt, not the amplitude, tells them apart.
    max_gait_tilt_rad : float
        ``tilt_rms_rad`` above which the motion is no gait but waving (a compass calibration turns the
        phone through +-60-90 deg; a swinging hand mostly stays within about +-45 deg) (rad), unless the
        gyroscope shows a gait's rotation: periodic at the stride about one axis while the norm is periodic
        (a hand swung hard, up to 10 rad/s, issue #25: waving is irregular and about every axis).
    twist_max_tilt_rad : float
        With a gyroscope: a rotation periodic at the stride but spread over the axes (main-axis share under
        ``swing_axis_share``: a hand swung with a twisting wrist, issue #25) is a gait's only while
        ``tilt_rms_rad`` is under this (rad).  A compass calibration can be as rhythmic and as spread (the IPIN
        tuning routes' first 25 s: rotation periodicity 0.8-0.95, main-axis share 0.5-0.7, 5-7 rad/s) but tilts
        the phone by 0.6-1.1 rad; the simulator's twisting swings tilt it by 0.27-0.50.
    twist_min_gyro_periodicity : float or None
        With a gyroscope: the rotation's periodicity at the stride (``gyro_periodicity``) from which a rotation spread
        over the axes is a gait's whatever its tilt (``twist_max_tilt_rad`` no longer applies); None: the tilt limit
        always applies.  Issue #25: the stride's periodicity, not the tilt, separates a gait from waving; a hand
        swung hard with a twisting wrist at a brisk cadence (the simulator's ``swing_scale`` 2 at 2.2 steps/s,
        twist 40 deg each way, 9.8 rad/s RMS) tilts by 0.52-0.57 rad with its rotation periodic at 0.98-1.00
        and was taken for waving ("not walking", 29 of 36 steps); the IPIN tuning routes' rhythmic calibrations
        repeat at 0.8-0.95.
    max_gait_rotation_rad_s : float
        With a gyroscope: RMS rotation above which a rotation spread over the axes
        (``gyro_axis_share`` under ``swing_axis_share``) is waving, not gait (rad/s).
    swing_axis_share : float
        Share of the rotation's variance on its main axis from which it is a pendulum: a fast rotation
        (``max_gait_rotation_rad_s``) spread over the axes is waving unless it is periodic at the stride
        (``rotation_periodic`` and the hard swing need the periodicity only, issue #25).
    screen_up_z : float
        ``gravity_b`` z component above which the screen faces up (hand-held).
    upright_y : float
        ``gravity_b`` y component above which the phone stands top up (ear).
    ear_incline_x : float
        ``|gravity_b x|`` above which an upright phone is inclined from the ear towards the mouth
        (in the screen's plane: 20-40 deg, ``sin`` 0.34-0.64), not upright in a pouch or bag.
    limb_tilt_rad, limb_stride_share : float
        Scales of the limb evidence ``tilt_rms_rad / limb_tilt_rad + stride_share / limb_stride_share``
        (a limb from 1.5: the tilt alone, or the two half-strides' difference alone, or both in part).
    min_limb_stride_share : float
        ... and in any case ``stride_share`` above this: a limb always sees its two half-strides
        differently; a trunk whose tilt is large but symmetric is waved, not walked with.
    arm_evidence : float
        ``stride_share + 0.3 horizontal_ratio`` (+ ``0.3 (gyro_rms - swing_gyro_rad_s)``, clipped to +-0.3)
        above which the limb is the swinging arm rather than a thigh: the hand's norm repeats only every
        stride (R(step) <= 0), its horizontal acceleration is large, it turns faster than a thigh.
    swing_gyro_rad_s : float
        With a gyroscope: the RMS rotation at which the gyroscope is neutral in the arm evidence (rad/s).
    hard_swing_gyro_rad_s : float
        With a gyroscope: an RMS rotation above this, periodic at the stride, is a swinging
        arm whatever the norm's stride share (a hard swing's centripetal acceleration repeats every step)
        (rad/s; a thigh turns at about 1.5, an arm swung normally at 2-2.5).
    hard_arm_gyro_rad_s, hard_arm_max_skew : float or None, float or None
        With a gyroscope (issue #25 section 2, h10/swing16): a rotation periodic at the stride (the gait's rotation of
        ``twist_min_gyro_periodicity`` and the rest) with an RMS above ``hard_arm_gyro_rad_s`` (rad/s; width 0.3)
        is a swinging arm's as ``hard_swing_gyro_rad_s`` is, unless the phone is read in the hand (screen up,
        pitched towards the face: the IPIN tuning routes' rhythmic compass calibrations, which with the limb
        evidence at 2.5 rad/s too counted 5-11 waving peaks as steps before their first landmark) or the rotation is
        skewed as a thigh's (``|skewness|`` above ``hard_arm_max_skew``, width 0.03: the simulator's brisk pockets turn
        at 2.1-2.25 rad/s RMS with a skew of 0.4-0.75 and were called a bag on a third more of their time without
        it; an arm's pendulum 0.03-0.26).  A hand swung hard at 1.4-1.6 steps/s (the simulator's ``swing_scale``
        2-2.5, 2.7-3.4 rad/s RMS, peaks 4-6 rad/s on the norm) has an arm evidence like a thigh's (stride share
        0.25-0.4, horizontal ratio 1.0) and a rotation under ``hard_swing_gyro_rad_s``: it was a pocket for the
        whole walk (pocket 0.6-0.7 against swinging 0.25-0.4 on every hop), counted with the hand-held gates, which
        miss a weak half-stride at the walk's start and its last steps.  Simulator (30-m walks, ``swing_scale``
        1.5-3, 1.4-1.8 steps/s, seeds 1-3, 60 walks): 2900 -> 2925 of 3000 heel strikes, no walk fewer; 2.8 and 3.0
        rad/s: +4 and +12 (at 2.8 a rotation on the threshold flaps between a bag and a swinging hand, whose gates
        differ: 2.5-rad/s-scale walks at 1.4 steps/s lost 3 steps each).  TUNING: identical (the 28 real walks, IPIN,
        Microsoft, IPOL, the carry benchmark's real recordings; its simulated swinging seeds 1.13 -> 1.08 % MAE).
        None: off, as before.
    thigh_min_skew : float or None
        Off by default (None); 0.32 turns it on.  With a gyroscope: ``gyro_skew`` (the ``|skewness|`` of the rotation
        rate about its main axis) from which a limb is the thigh, not the arm, whatever the arm evidence (issue #25).
        No real tuning recording shows it helping (the one real pocket walk with a gyroscope, lopen, is called "bag"
        either way), and with it on the report clips seen once (real_walks at 7baa561) lost more steps: Omer1Eryilmaz
        pockets 34/41/36/39 -> 18/27/36/36, waving hands 34/27 -> 17/0 (in a pocket the rotation gate stays at its
        hand-held limit, which a swinging hand taken for a thigh exceeds).  The thigh extends slowly through
        stance and flexes quickly in swing (its rate is skewed); an arm swings as a pendulum, the same both ways.
        The tuning walk thomasdingemanse_lopen (trouser pocket by inference) reads 0.22 / 0.30 / 0.38 (quartiles
        over 4-s windows; it is called "bag", a trunk, so the arm evidence does not apply to it), the simulator's
        calibrated pocket 0.48-0.69, its swinging hand (gentle to hard, with a twisting wrist) 0.03-0.14 over whole
        walks and up to 0.26 in single windows of a short hard swing (a window of a non-whole number of strides).  A soft-soled pocket walk (the simulator's pocket with a third of its heel
        strikes) has an arm's stride share and horizontal acceleration: only the rotation's shape tells it apart.
    uneven_on_share, uneven_off_share : float
        :attr:`uneven` turns on when a walking window's ``stride_share`` reaches ``uneven_on_share`` and off under
        ``uneven_off_share`` (a band, so that it does not flap), when not walking or when the screen faces up or down
        (``|gravity_z| >= screen_up_z``: a phone in a trouser pocket stands along the thigh or on its edge; every
        tuning pocket reads ``|gravity_z|`` under 0.2, the simulator's under 0.1): the two half-strides are so
        unlike (the norm's step-lag autocorrelation a fifth of its stride-lag one or less) that every other valley
        can stay above ``g`` and every other peak under ``A_th``.  The pipeline then counts a pocket's steps with
        the limb gates (:data:`core.pdr.steps.UNEVEN_POCKET`, issue #25).  **Off by default** (``inf``; 0.75 turns it
        on, with ``thigh_min_skew=0.32`` so that a soft-soled pocket is called a pocket at all): on every real tuning
        recording it changes nothing (the 13 yh570 counted clips, 4 of them trouser pockets, identical; psy901 105 ->
        105) but one step of lopen (602 -> 603), so only the simulator shows its gain; the guard's Oxford placements
        move 1.923 -> 1.940 % (a back pocket's 268 -> 269 of 257).  The simulator's pocket reads 0.22-0.37
        (counted within 1 % with the hand-held gates), with a third of its heel strikes (soft soles) 0.9-1.07 (23
        of 42 steps with the hand-held gates, 41 with the limb gates); the tuning clip psy901 0.52 in the median
        (105 steps with 0.75 / 0.6, as without; 106 with 0.6 / 0.45: each switch of detector can add a step); the
        tuning walk lopen 0.07.
    switch_s : float
        A new walking mode must win for this long before it replaces the current one (s).
    switch_still_s : float
        The same for changes from or to ``still`` (s).
    hold_periodicity, hold_recent_s, hold_min_std_m_s2 : float
        A walk goes on while its gait is periodic (issue #25): once the mode is a walking one, the norm's
        periodicity (``min_periodicity`` to start a walk) need only be above ``hold_periodicity`` while the norm's
        standard deviation over the window's last ``hold_recent_s`` seconds (``recent_std_m_s2``) is at least
        ``hold_min_std_m_s2`` (m/s^2; above a phone held while standing, 0.1-0.3).  A turn or a change of pace
        lowers a 4-s window's autocorrelation at the stride to 0.2-0.35 for 2-5 s while the steps go on (the
        yh570 tuning clips' lap turns: a hand-held walk was "still" 30 % of its time); a stop empties the end of the
        window first, so the hold ends with it (IPOL's stops are called as soon as before).  Amplitude and
        waving gates are unchanged: a phone held still, on a table or waved is not held in a walk.
    settle_while_still : bool
        Off by default.  True: :attr:`settling` (the pipeline holds a walk's steps meanwhile,
        ``Pipeline(hold_while_settling=True)``) whenever the mode in force is ``still``, after the first window too;
        False: only while a walking mode waits out the hysteresis from ``still``.  Issue #25: a slow walk that the
        detector calls "not walking" for its first seconds (the tuning clip Tclack88 50_hand_slow: raw "still" until
        7.5 s) can have its first steps completed with the hand-held gates before the walking decision, and the
        gentle detector's held peaks then no longer replace them: the clip with its first 0.1-0.4 s cut off (other
        hop phases) counts 49/44/45/51 of 50 without this, 49/48/49/51 with it, every other tuning clip the same
        (mean absolute error over the 26 clips and 5 cuts 2.26 -> 2.13 %).  Not the default: on the simulator's
        tuning swinging clip (seed 3, ``tests/test_carry.py``) it counts 40 of 44 instead of 43, because the settled
        mode's detector, whose first seconds miss steps of their own (no step period yet), then replaces every held
        step, also those the hand-held gates had right.
    settle_walk_s : float
        Issue #25, a swinging hand's first steps.  A walk's mode is first decided on one 4-s window (the first
        window of the recording, or the change from ``still``), and that first call is often a neighbour of the
        right one (a hand swung at 3-9 rad/s is first called a pocket or a bag, then a swinging hand 3 s later,
        after ``switch_s``).  With ``settle_walk_s`` > 0 :attr:`settling` stays True for this long (s) after that
        first walking decision, and on while a change to another walking mode that began within it waits out its
        hysteresis (:attr:`pending_mode`; so at most ``settle_walk_s + switch_s``): the pipeline holds the walk's
        first steps meanwhile and the settled mode's detector recounts them
        (``Pipeline(hold_while_settling=True, recount_at_settle=True)``).  **1.0, the default** (two hops: the
        first call's rival shows within a hop or two; 0: off, as before).  Simulator (64 swinging 34-m walks,
        ``swing_scale`` 1-2.5, twist 8 or 25 deg, 1.6-2.0 steps/s, standing 0.3 or 3 s first, seeds 1-2): heel
        strikes missed 248 -> 217 of 3232 (in the walk's first 8 s 148 -> 117), no step added; with 3.0, 214.  TUNING
        (real walks, IPIN, Microsoft, IPOL): identical (benchmarks/discussion.md).  The live app sees such a walk's
        first steps up to ``settle_walk_s + switch_s`` late (never more than the pipeline's ``rotation_hold_s``).
    sway_min_gyro_periodicity : float or None
        Issue #25 section 2 (h11/slowhand), **0.9 by default**; None: off.  With a gyroscope, at a slow stride
        (``slow_stride_s`` or longer) on the trunk (``tilt_rms_rad`` under ``trunk_max_tilt_rad``), a gait with both
        legs is also the norm repeating from one foot to the other (the step lag's autocorrelation) while the trunk's
        sway, once per stride, repeats at the stride lag with at least this periodicity: :meth:`gait_periodicity`
        takes ``min(r_step, gyro_periodicity)`` too.  At 1 step/s the stride lag (2 s) of a 4-s window overlaps one
        stride and its autocorrelation reads 0.2-0.5 where the step lag reads 0.6-0.75 (the step times' jitter adds
        up over two steps); the simulator's hand-held walk at 1 step/s, bounce 1.6 (user acceleration 0.5 m/s^2 RMS),
        was "not walking" 95 % of the time and counted 0 of 40.  A phone held while standing reads at most 0.62 at
        the stride lag of its rotation, a vehicle 0.40 (the simulator's ten not-walking recordings, the fidgeting
        hand of ``tests/test_carry.py``).
    antiphase_in_range : bool
        Issue #25 section 2 (h11/slowhand), **on by default**.  :meth:`gait_periodicity` leaves a step lag in
        anti-phase (``step_antiphase``) to the norm's rule only while twice the stride found is a walk's stride too
        (up to the longest stride searched, ``max(max_stride_s, slow_window_max_stride_s)``, 2.8 s): only then can
        the lag be a trunk's step.  Past it (a gently swung hand at 1.2 steps/s: stride 1.64 s, step lag
        -0.16..-0.34, rotation periodic at 0.93-0.98) the lag is a limb's stride; the rule called it "not walking"
        whenever the step lag dipped under -0.2 (10 of 34 steps).  With ``max_stride_s`` (2.5 s) as the bound, a
        trunk at 0.8 steps/s (its step 1.25-1.3 s) was taken for a limb (the simulator's ear, 26 -> 24 of 26 steps).
        False: as before.
    ear_max_swing_deg : float or None
        Issue #25 (h14/swingear), with a gyroscope: the rotation's swing per stride (:meth:`stride_swing_deg`, deg)
        above which a phone that stands upright as at the ear (``upright_y``, ``ear_incline_x``) is on a limb, not at
        the ear: the ear's score goes to the swinging hand; width 2 deg.  A phone pressed to the ear turns with the
        head, a few degrees per stride (the simulator's ear +-2 deg of yaw, +-1.5 of pitch); a hand swung with the
        phone upright turns about the shoulder by tens of degrees, and a pendulum's specific force stays along the
        arm, so the tilt (``tilt_rms_rad`` 0.19 rad) and the norm (the centripetal term the same at both passes:
        stride share 0) read as a trunk's and only the gyroscope sees the limb.  The TUNING Tyrex walks ``Jakob_Nexus5_*_Swinging``:
        their hops called "ear" swing 44-45 deg per stride (median; 10th percentile 23-29) at 2.5 rad/s RMS, on the
        edge of ``hard_arm_gyro_rad_s``; the simulator's ear reads 3.0 (at most 3.8), the other tuning truth walks' raw
        "ear" hops (OxIOD and Jakob's pockets, a RIDI bag) at most 10-27.  **On by default (20 deg) since
        h15/swingsteps, for the steps** (None: off, as before): a swung hand called "ear" keeps the ear's 3 rad/s
        rotation gate, and Jakob's swinging walks lost their steps there (1-s rotation RMS 3.0-3.5 rad/s at the
        refused peaks, periodic at the stride).  TUNING: Jakob's six swinging walks against the Tyrex step truth
        (:func:`benchmarks.truth_walks.step_truth`) 727 -> 753 of 784 steps (median absolute error 6.6 -> 2.4 %, mean
        -7.2 -> -3.8 %; 5 of 6 closer), the 30 other tuning truth walks, the 28 real tuning walks (the 26 counted
        clips 1.489 %), the main benchmark's 92 tuning recordings and the carry benchmark's 60 tuning seeds
        identical; the walking direction of the same six: offset error against the truth 90.9 -> 24.6 deg (median),
        but end error after the best rotation 6.7 -> 7.3 % (the offset applied to part of a walk:
        ``benchmarks/discussion.md``, h14/swinglimb).  One walker (``benchmarks/discussion.md``, h15/swingsteps).
        Before that it was off: on the TUNING split of its time (24 truth walks, the phase-axis rule off) it changed
        one walker's two walks only.  With 20 (15 and 25 give the same): Jakob's
        swinging walks called "ear" 55 -> 0 % and 10 -> 0 % of the time, the offset error against the truth attitude
        96.5 -> 15.3 and 118.8 -> 99.8 deg (median; steps over 90 deg off 54 -> 23 %, 74 -> 58 %), end error after the
        best rotation 1.2 -> 1.2 and 20.3 -> 10.8 % of the path, distance -23.9 -> -21.0 and -15.2 -> -13.9 %; every
        other tuning truth walk (22), the 28 real walks, the carry benchmark's tuning recordings (simulator, IPOL,
        IPIN) and the main benchmark's 92 (IPIN, Microsoft, IPOL) identical (``benchmarks/discussion.md``).  On the
        same walker's four iPhone swinging walks added to the tuning split afterwards (the lead, the phase-axis rule
        on; out of sample for the setting): "ear" 0 / 61 / 43 / 78 % -> 0, offset error 8.9 / 89.9 / 67.8 / 91.8 ->
        8.5 / 75.8 / 31.6 / 17.7 deg, but end error 7.5 / 6.5 / 4.5 / 7.0 -> 6.9 / 7.7 / 5.3 / 10.7 %: mixed, then off
        (why the shape suffers: ``Pipeline(cross_axis_modes)``).
    hand_limb_min_tilt_rad, hand_limb_max_swing_deg : float or None, float or None
        Issue #25/#27 (h15/handheld), **on by default (0.2 rad, 30 deg)**; ``hand_limb_min_tilt_rad=None``: off, as
        before.  A phone read in the hand (screen up, pitched towards the face: the hand's evidence of ``screen_up_z``
        and the rest) that neither tilts (``tilt_rms_rad`` under ``hand_limb_min_tilt_rad``, width 0.03 rad) nor, with
        a gyroscope, swings (:meth:`stride_swing_deg` under ``hand_limb_max_swing_deg``, width 2 deg; None: the tilt
        alone) is held in front of the body, not on a limb: the limb evidence is multiplied by ``1 - hand * (1 -
        sig(tilt)) * (1 - sig(swing))``.  Without it the limb evidence could come from the norm alone (``stride_share
        / limb_stride_share``): the Microsoft TUNING traces (every one hand-held, the phone flat: gravity z
        0.99-1.00, tilt 0.05-0.16 rad) had walks' first windows and stray hops whose norm repeats at two steps' lag
        (stride share 0.5-1.2 at lags of 2.1-2.4 s) called "pocket", and the first window's call is taken at once and
        held by the hysteresis for 3-4.5 s: 31 of their 711 steps (4.4 %; 5dd39012 8 of 23, the walking-direction
        offset turning one step by 155 deg).  With it: 0 of 711 (0 raw hops off the hand, 56 before), the IPIN tuning
        routes 3 of 2278 as before (a compass calibration's tilt of 0.4-0.7 rad at T01r01's start, left alone; raw hops
        off the hand 115 -> 38, all waving at 0.3-0.7 rad), every step count identical.  The swing: a hand swung with
        the phone upright and its screen partly up (the TUNING Tyrex walk Jakob_iPhone5_Dist_Swinging: the hand's
        evidence 0.5-0.8, tilt 0.16-0.25 rad, as small as a pendulum's specific force allows) turns by 40-65 deg a
        stride; with the tilt alone 22 % of that walk was hand-held (7 % before), 5 steps lost; with the swing
        identical to before (the flat hand-held hops that the rule turns read 0-27 deg, median 0).  The simulator's
        carry tuning seeds 0-9, the 28 real tuning walks and the Tyrex tuning walks identical; OxIOD's tuning
        hand-held walks lose their 3-4 % of "pocket" (benchmarks/discussion.md, h15/handheld).  The simulator's
        pocket reads the hand's evidence at most 0.09 (gravity z 0.12-0.16), its swinging hand 0.
    """

    def __init__(self, *, grid_rate_hz: float = 50.0, window_s: float = 4.0, hop_s: float = 0.5,
                 tilt_smooth_s: float = 0.2, min_stride_s: float = 0.8, max_stride_s: float = 2.5,
                 slow_window_s: float = 5.0, slow_window_max_stride_s: float = 2.8, slow_window_stride_s: float = 2.1, slow_window_max_std_m_s2: float = 1.2,
                 slow_window_min_periodicity: float = 0.6, slow_window_while_still: bool = True,
                 slow_stride_s: float = 1.6, slow_stride_margin: float = 0.7, slow_stride_edge: bool = True,
                 half_stride_ratio: float = 0.5,
                 min_walk_std_m_s2: float = 0.6, min_periodicity: float = 0.35, gentle_min_std_m_s2: float = 0.12,
                 gentle_min_periodicity: float = 0.6, gentle_max_std_m_s2: float = 0.5, slow_max_std_m_s2: float = 1.0,
                 slow_off_std_m_s2: float = 1.2,
                 slow_min_std_m_s2: float = 0.4, slow_min_periodicity: float = 0.4, slow_hold: bool = True,
                 step_antiphase: float = -0.2, trunk_min_periodicity: float = 0.4, trunk_max_tilt_rad: float = 0.15, max_gait_tilt_rad: float = 0.6, twist_max_tilt_rad: float = 0.55,
                 twist_min_gyro_periodicity: float | None = 0.97,
                 max_gait_rotation_rad_s: float = 4.5, swing_axis_share: float = 0.85, screen_up_z: float = 0.3,
                 upright_y: float = 0.6, ear_incline_x: float = 0.22, limb_tilt_rad: float = 0.16,
                 limb_stride_share: float = 0.3, min_limb_stride_share: float = 0.15, arm_evidence: float = 1.1,
                 swing_gyro_rad_s: float = 2.0, hard_swing_gyro_rad_s: float = 3.5,
                 hard_arm_gyro_rad_s: float | None = 2.5, hard_arm_max_skew: float | None = 0.32,
                 thigh_min_skew: float | None = None,
                 uneven_on_share: float = math.inf, uneven_off_share: float = 0.6,
                 switch_s: float = 3.0, switch_still_s: float = 2.0, hold_periodicity: float = 0.2, hold_recent_s: float = 1.0,
                 hold_min_std_m_s2: float = 0.3, settle_while_still: bool = False, settle_walk_s: float = 1.0,
                 sway_min_gyro_periodicity: float | None = 0.9, antiphase_in_range: bool = True,
                 ear_max_swing_deg: float | None = 20.0, hand_limb_min_tilt_rad: float | None = 0.2,
                 hand_limb_max_swing_deg: float | None = 30.0):
        self.grid_rate_hz = float(grid_rate_hz)
        self.window_s = float(window_s)
        self.hop_s = float(hop_s)
        self.tilt_smooth_s = float(tilt_smooth_s)
        self.min_stride_s = float(min_stride_s)
        self.max_stride_s = float(max_stride_s)
        self.slow_window_s = float(slow_window_s)
        self.slow_window_stride_s = float(slow_window_stride_s)
        self.slow_window_max_stride_s = float(slow_window_max_stride_s)
        self.slow_window_max_std_m_s2 = float(slow_window_max_std_m_s2)
        self.slow_window_min_periodicity = float(slow_window_min_periodicity)
        self.slow_window_while_still = bool(slow_window_while_still)
        self.slow_stride_s = float(slow_stride_s)
        self.slow_stride_margin = float(slow_stride_margin)
        self.slow_stride_edge = bool(slow_stride_edge)
        self.half_stride_ratio = float(half_stride_ratio)
        self.min_walk_std_m_s2 = float(min_walk_std_m_s2)
        self.min_periodicity = float(min_periodicity)
        self.gentle_min_std_m_s2 = float(gentle_min_std_m_s2)
        self.gentle_min_periodicity = float(gentle_min_periodicity)
        self.gentle_max_std_m_s2 = float(gentle_max_std_m_s2)
        self.slow_max_std_m_s2 = float(slow_max_std_m_s2)
        self.slow_off_std_m_s2 = float(slow_off_std_m_s2)
        self.slow_min_std_m_s2 = float(slow_min_std_m_s2)
        self.slow_min_periodicity = float(slow_min_periodicity)
        self.slow_hold = bool(slow_hold)
        self.step_antiphase = float(step_antiphase)
        self.trunk_min_periodicity = float(trunk_min_periodicity)
        self.trunk_max_tilt_rad = float(trunk_max_tilt_rad)
        self.max_gait_tilt_rad = float(max_gait_tilt_rad)
        self.twist_max_tilt_rad = float(twist_max_tilt_rad)
        self.twist_min_gyro_periodicity = None if twist_min_gyro_periodicity is None else float(twist_min_gyro_periodicity)
        self.max_gait_rotation_rad_s = float(max_gait_rotation_rad_s)
        self.swing_axis_share = float(swing_axis_share)
        self.screen_up_z = float(screen_up_z)
        self.upright_y = float(upright_y)
        self.ear_incline_x = float(ear_incline_x)
        self.limb_tilt_rad = float(limb_tilt_rad)
        self.limb_stride_share = float(limb_stride_share)
        self.min_limb_stride_share = float(min_limb_stride_share)
        self.arm_evidence = float(arm_evidence)
        self.swing_gyro_rad_s = float(swing_gyro_rad_s)
        self.hard_swing_gyro_rad_s = float(hard_swing_gyro_rad_s)
        self.hard_arm_gyro_rad_s = None if hard_arm_gyro_rad_s is None else float(hard_arm_gyro_rad_s)
        self.hard_arm_max_skew = None if hard_arm_max_skew is None else float(hard_arm_max_skew)
        self.thigh_min_skew = None if thigh_min_skew is None else float(thigh_min_skew)
        self.uneven_on_share = float(uneven_on_share)
        self.uneven_off_share = float(uneven_off_share)
        self.switch_s = float(switch_s)
        self.switch_still_s = float(switch_still_s)
        self.hold_periodicity = float(hold_periodicity)
        self.hold_recent_s = float(hold_recent_s)
        self.hold_min_std_m_s2 = float(hold_min_std_m_s2)
        self.settle_while_still = bool(settle_while_still)
        self.settle_walk_s = float(settle_walk_s)
        self.sway_min_gyro_periodicity = (None if sway_min_gyro_periodicity is None
                                          else float(sway_min_gyro_periodicity))
        self.antiphase_in_range = bool(antiphase_in_range)
        self.ear_max_swing_deg = _optional_angle("ear_max_swing_deg", ear_max_swing_deg, "deg")
        self.hand_limb_min_tilt_rad = _optional_angle("hand_limb_min_tilt_rad", hand_limb_min_tilt_rad, "rad")
        self.hand_limb_max_swing_deg = _optional_angle("hand_limb_max_swing_deg", hand_limb_max_swing_deg, "deg")
        self.reset()

    def reset(self) -> None:
        n = self._n = max(8, int(round(self.window_s * self.grid_rate_hz)))
        #: the ring's length: the long window of a very slow walk's stride (``slow_window_s``), else the window
        self._n_long = max(n, int(round(self.slow_window_s * self.grid_rate_hz)))
        self._hop = max(1, int(round(self.hop_s * self.grid_rate_hz)))
        self._smooth = max(1, int(round(self.tilt_smooth_s * self.grid_rate_hz)))
        self._recent = min(n, max(2, int(round(self.hold_recent_s * self.grid_rate_hz))))
        self._lag_lo = max(2, int(self.min_stride_s * self.grid_rate_hz))
        self._lag_hi = min(n - 8, int(math.ceil(self.max_stride_s * self.grid_rate_hz)))
        #: the longest stride lag of a gentle norm's window (slow_window_max_stride_s), before the window's own bound
        self._lag_hi_slow = (int(math.ceil(self.slow_window_max_stride_s * self.grid_rate_hz))
                             if self._n_long > n else self._lag_hi)
        self._lag_short = max(self._lag_lo + 2, min(self._lag_hi, int(math.ceil(self.slow_stride_s * self.grid_rate_hz))))
        self._nfft = 1 << int(math.ceil(math.log2(2 * self._n_long)))
        self._scratch_n = {}  # window length -> compute_features' work arrays
        self._buf = np.zeros((self._n_long, 6))  # ax ay az gx gy gz, ring
        self._k = 0  # next row of the ring
        self._filled = 0
        self._since_hop = 0
        self._has_gyro = False
        #: current mode (one of core.conventions.CARRY_MODES) and its confidence 0..1
        self.mode = CARRY_HANDHELD
        self.confidence = 0.0
        self._decided = False
        self._cand = None
        self._cand_ns = 0
        self._cand_conf = 0.0
        #: raw (per-hop) decision and its confidence, before the hysteresis
        self.raw_mode = CARRY_HANDHELD
        self.raw_confidence = 0.0
        #: mode changes in time order
        self.changes: list[CarryChange] = []
        #: seconds spent in each mode (grid samples / rate)
        self.time_s = {m: 0.0 for m in CARRY_MODES}
        #: step period (s) from the autocorrelation of the norm (nan until known or when not walking)
        self.step_period_s = math.nan
        #: the phone's rotation is periodic at the stride while the norm is (a swinging arm), not irregular (waving)
        self.rotation_periodic = False
        #: the last window's periodicity at both legs' lags (:meth:`gait_periodicity`) while the step period is known
        #: (nan otherwise)
        self.both_periodicity = math.nan
        #: the last window's norm standard deviation (m/s^2) while the step period is known (nan otherwise): the
        #: gait's own amplitude, for the step detector's ``relative_peak_height`` (:class:`core.pdr.steps.StepGates`)
        self.gait_std_m_s2 = math.nan
        #: walking gently (a periodic gait whose norm moves little; see ``gentle_max_std_m_s2``)
        self.gentle = False
        #: the two half-strides are very unlike (see ``uneven_on_share``)
        self.uneven = False
        #: the mode of a walk is not settled yet (issue #25): before the first full window, and while the mode is
        #: ``still`` (with ``settle_while_still`` False: only while a walking mode waits out its hysteresis).  The
        #: pipeline holds its steps meanwhile, so that the walking mode that follows counts them with its own gates
        #: (both legs of a limb)
        self.settling = True
        #: when the walk's first walking mode was decided (``settle_walk_s``; None: no walk start open)
        self._walk_start_ns = None
        #: :attr:`settling` only by ``settle_walk_s`` (a walking mode in force, the walk's start held open)
        self.settling_walk = False
        #: the last hop's features (name -> float) and mode scores (mode -> float), for diagnostics
        self.features: dict = {}
        self.scores: dict = {}
        self.n_hops = 0
        #: hops that took the long window's features (``slow_window_s``), for diagnostics
        self.n_slow_window_hops = 0
        self._dt = 1.0 / self.grid_rate_hz

    # -- streaming ------------------------------------------------------------
    def update_grid(self, t_ns: int, ax: float, ay: float, az: float, gx: float | None = None,
                    gy: float | None = None, gz: float | None = None) -> str:
        """One grid sample (acc m/s^2, gyro rad/s or None); returns the current mode."""
        row = self._buf[self._k]
        if gx is None:
            row[0], row[1], row[2], row[3], row[4], row[5] = ax, ay, az, 0.0, 0.0, 0.0
        else:
            row[0], row[1], row[2], row[3], row[4], row[5] = ax, ay, az, gx, gy, gz
            self._has_gyro = True
        self._k = (self._k + 1) % self._n_long
        if self._filled < self._n_long:
            self._filled += 1
        self.time_s[self.mode] += self._dt
        self._since_hop += 1
        if self._since_hop >= self._hop and self._filled >= self._n:
            self._since_hop = 0
            self._hop_decision(t_ns)
        return self.mode

    def restart(self) -> None:
        """A gap in the data: the window starts again (the mode is kept)."""
        self._filled = 0
        self._since_hop = 0

    # -- the desktop fast path's way in (desktop/fast/carry.py: it computes every hop's features at once) ----------
    @property
    def kernel_settings(self) -> dict:
        """The grid lengths :meth:`reset` derives from the settings: ``window_n`` and ``long_window_n`` (samples of
        the window and of the slow walk's long one), ``hop_n``, ``smooth_n`` (the tilt's smoothing), ``recent_n``
        (the hold's recent part), ``lag_lo_n``, ``lag_hi_n``, ``lag_short_n`` (stride lags), ``nfft`` (the
        autocorrelation's FFT length) and ``dt_s`` (the grid period)."""
        return {"window_n": self._n, "long_window_n": self._n_long, "hop_n": self._hop, "smooth_n": self._smooth,
                "recent_n": self._recent, "lag_lo_n": self._lag_lo, "lag_hi_n": self._lag_hi,
                "lag_short_n": self._lag_short, "nfft": self._nfft, "dt_s": self._dt}

    @property
    def has_gyro(self) -> bool:
        """Whether a grid sample with the gyroscope came in since :meth:`reset` (the features then use it)."""
        return self._has_gyro

    def set_gyro_seen(self, seen: bool) -> None:
        """Set :attr:`has_gyro` (a bool): the fast path, which feeds no grid samples, sets it as they would have
        left it at each hop and after the last sample.  :meth:`update_grid` sets it on the per-sample path itself."""
        if not isinstance(seen, bool):
            raise TypeError(f"set_gyro_seen takes a bool, not {type(seen).__name__}")
        self._has_gyro = seen

    # -- features ---------------------------------------------------------------
    def _autocorr(self, x: np.ndarray) -> np.ndarray:
        """Autocorrelation at lags 0..n-1 of each row of ``x`` (zero-mean signals, 2-D), normalised by its
        lag 0 (a row whose lag 0 is under 1e-12 gives zeros), not yet unbiased: ``r(k) n_k / (n_k - k)``
        for a row of ``n_k`` samples (the rest of the row zero-padded)."""
        n = x.shape[-1]
        f = np.fft.rfft(x, self._nfft)  # one batched transform for all the rows (the last axis)
        r = np.fft.irfft(f * np.conj(f), self._nfft)[..., :n]
        r0 = r[..., :1]
        out = r / np.where(r0 > 1e-12, r0, 1.0)
        out[r0[..., 0] <= 1e-12] = 0.0
        return out

    def compute_features(self, w: np.ndarray) -> dict:
        """The features of one window ``w`` (n, 6: acc xyz, gyro xyz, oldest first).

        Written for few numpy calls (this runs on the phone every ``hop_s``): the two or three
        autocorrelations share one batched FFT, the two 3 x 3 eigenproblems one ``eigh``.
        """
        n = len(w)
        scratch = self._scratch_n.get(n)
        if scratch is None:  # the unbiased autocorrelation's factor at lags 0..n-1; the acceleration's running
            # sums (row 0 stays 0); the autocorrelated signals: the norm, the tilt's swing, the rotation
            scratch = self._scratch_n[n] = (n / (n - np.arange(n)), np.zeros((n + 1, 3)), np.zeros((3, n)))
        unbias, c, rows = scratch
        acc = w[:, :3]
        norm = np.sqrt(np.einsum("ij,ij->i", acc, acc))
        m = np.add.reduce(acc, axis=0) / n
        m_norm = math.sqrt(float(m.dot(m)))
        mean_norm = float(np.add.reduce(norm)) / n
        u = m / m_norm if m_norm > 1e-6 else np.array([0.0, 0.0, 1.0])
        x = norm - mean_norm
        std = math.sqrt(float(np.add.reduce(x * x)) / n)
        xr = norm[n - min(self._recent, n):]
        xr = xr - float(np.add.reduce(xr)) / len(xr)
        recent_std = math.sqrt(float(np.add.reduce(xr * xr)) / len(xr))
        # smoothed direction of the specific force and its angle from the mean direction
        np.cumsum(acc, axis=0, out=c[1:])
        s = self._smooth
        sm = (c[s:] - c[:-s]) / s
        smn = np.sqrt(np.einsum("ij,ij->i", sm, sm))
        den = np.maximum(smn, 1e-9)
        cosang = np.clip((sm @ u) / den, -1.0, 1.0)
        ang = np.arccos(cosang)
        tilt_rms = math.sqrt(float(np.add.reduce(ang * ang)) / len(ang))
        # tilt periodicity: the component of the smoothed direction along its main swing axis
        d = sm / den[:, None] - u
        dyn = acc - m
        cov_a = dyn.T @ dyn / n
        if self._has_gyro:
            gyr = w[:, 3:]
            gm = np.add.reduce(gyr, axis=0) / n
            gc = gyr - gm
            evals, evecs = np.linalg.eigh(np.stack([d.T @ d, gc.T @ gc]))
            ge, gv = evals[1], evecs[1]
            evecs = evecs[0]
        else:
            evals, evecs = np.linalg.eigh(d.T @ d)
        swing = d @ evecs[:, -1]
        swing -= float(np.add.reduce(swing)) / len(swing)
        rows = rows[:3 if self._has_gyro else 2]  # the signals, zero-padded to n (row 1's tail stays 0)
        rows[0] = x
        rows[1, :len(swing)] = swing
        if self._has_gyro:
            np.matmul(gc, gv[:, -1], out=rows[2])
        r_all = self._autocorr(rows)
        r = r_all[0] * unbias
        lo, hi = self._lag_lo, self.lag_hi(n, std)
        seg = r[lo:hi + 1]
        top = float(seg.max())
        short = seg[:self._lag_short - lo + 1]
        use_short = float(short.max()) >= self.slow_stride_margin * top
        full = seg
        if use_short:  # a normal cadence's stride (see slow_stride_s)
            seg = short
            top = float(seg.max())
        # the shortest lag that is a local maximum within 85 % of the best: the stride, not two of them
        peaks = np.flatnonzero((seg[1:-1] >= seg[:-2]) & (seg[1:-1] >= seg[2:]) & (seg[1:-1] >= 0.85 * top)) + 1
        if use_short and not len(peaks) and self.slow_stride_edge:
            # no peak in the normal cadence's range, its best on the edge (``slow_stride_edge``): the stride is the
            # peak that straddles the edge (1.2 steps/s: a stride of 1.67 s just past slow_stride_s)
            e = len(short) - 1
            while e + 1 < len(full) and full[e + 1] >= full[e]:
                e += 1
            seg = full[:e + 2]
            top = float(seg.max())
            peaks = np.flatnonzero((seg[1:-1] >= seg[:-2]) & (seg[1:-1] >= seg[2:]) & (seg[1:-1] >= 0.85 * top)) + 1
        k2 = lo + (int(peaks[0]) if len(peaks) else int(np.argmax(seg)))
        if not use_short and len(peaks):
            k2 = self._half_stride(r, k2)
        k2 = self._stride_lag(r, r_all[2] if self._has_gyro else None, k2, n, tilt_rms, hi)
        ks = k2 // 2
        r_step = float(r[max(1, ks - 2):ks + 3].max())
        r_stride = float(r[k2])
        if not len(peaks):  # no stride inside the range (a maximum on its edge): no stride share either
            r_step = r_stride = min(r_step, r_stride)
        ns = len(swing)
        tilt_stride = float(r_all[1, k2]) * (ns / (ns - k2)) if ns > k2 else 0.0
        vert = float(u @ cov_a @ u)
        horiz = max(float(np.trace(cov_a)) - vert, 0.0)
        f = {
            "gravity_x": float(u[0]), "gravity_y": float(u[1]), "gravity_z": float(u[2]),
            "tilt_rms_rad": tilt_rms, "coherence": m_norm / mean_norm if mean_norm > 1e-6 else 1.0,
            "acc_std_m_s2": std, "recent_std_m_s2": recent_std, "periodicity": max(r_step, r_stride), "r_step": r_step, "r_stride": r_stride,
            "stride_share": r_stride - r_step, "stride_period_s": k2 / self.grid_rate_hz,
            "tilt_stride_corr": tilt_stride, "horizontal_ratio": math.sqrt(horiz / vert) if vert > 1e-9 else 0.0,
        }
        if self._has_gyro:
            g_rms = math.sqrt(float(np.add.reduce(np.einsum("ij,ij->i", gyr, gyr))) / n)
            share = float(ge[-1] / max(float(np.sum(ge)), 1e-12))
            f.update(gyro_rms_rad_s=g_rms, gyro_axis_share=share, gyro_periodicity=float(r_all[2, k2]) * (n / (n - k2)),
                     gyro_skew=rotation_skew(rows[2]))
        return f

    def lag_hi(self, n: int, std: float) -> int:
        """The longest stride lag searched in a window of ``n`` samples whose norm's standard deviation is ``std``
        (m/s^2): ``slow_window_max_stride_s`` in the long window (``slow_window_s``) of a gentle norm
        (``slow_window_max_std_m_s2``), ``max_stride_s`` otherwise (the ``window_s`` window's range is the same with
        the long window on or off: on the TUNING walk yh570 hand_1_28_21_35 the longer range there alone called a
        hand-held walk a pocket for 7 s)."""
        if n == self._n_long > self._n and std < self.slow_window_max_std_m_s2:
            return min(n - 8, self._lag_hi_slow)
        return min(n - 8, self._lag_hi)

    def _half_stride(self, r: np.ndarray, k2: int) -> int:
        """A slow stride's lag ``k2`` (past ``slow_stride_s``) halved when the norm's (unbiased) autocorrelation
        ``r`` has a local maximum within 2 samples of ``k2 / 2`` at least ``half_stride_ratio`` of ``r[k2]``: the
        lag found was two strides (see ``half_stride_ratio``)."""
        half = k2 // 2
        if self.half_stride_ratio <= 0.0 or half < self._lag_lo:
            return k2
        vals = r[half - 2:half + 3]
        j = int(np.argmax(vals))
        if 0 < j < len(vals) - 1 and vals[j] >= self.half_stride_ratio * r[k2]:
            return half - 2 + j
        return k2

    def _stride_lag(self, r: np.ndarray, r_gyro: np.ndarray | None, k2: int, n: int, tilt_rms: float,
                    hi: int) -> int:
        """The stride lag from the lag ``k2`` found in the norm's (unbiased) autocorrelation ``r``: twice it when
        ``k2`` is a slow walk's step and twice it is in range.  The norm in anti-phase at ``k2 / 2``
        (``step_antiphase``) makes ``k2`` one period of the norm: a trunk's step (both feet alike) or a limb's
        stride (its two half-strides unlike).  The phone is on the trunk, and ``k2`` its step, when the norm
        clearly repeats at ``k2`` (``trunk_min_periodicity``) and the phone tilts less than ``trunk_max_tilt_rad`` (issue #25: a limb swings by +-20-45 deg, the trunk sways by a few) or
        when the rotation's main axis (autocorrelation ``r_gyro``, not yet unbiased), which a walker sways once
        per stride, is in anti-phase at ``k2`` too."""
        k4 = 2 * k2
        if k4 > hi or r[k2 // 2] >= self.step_antiphase:
            return k2
        if tilt_rms < self.trunk_max_tilt_rad and r[k2] >= self.trunk_min_periodicity:
            return k4
        if r_gyro is None or float(r_gyro[k2]) * (n / (n - k2)) >= self.step_antiphase:
            return k2
        return k4

    def gait_periodicity(self, f: dict) -> float:
        """How periodic a gait with both legs is, from one window's features (issue #25): the norm's
        autocorrelation at both the step and the stride lag (a trunk sees both feet alike), or, with a
        gyroscope, at the stride lag together with the rotation's there while the step lag is not in
        anti-phase (``step_antiphase``): a limb sees its two half-strides differently (the norm's step-lag
        autocorrelation 0.3-0.5 in a gentle walk), and the rotation, swung once per stride, repeats with the
        norm.  An anti-phase step lag is left to the first rule while twice the stride is in range
        (``antiphase_in_range``): at 1 step/s a trunk's norm is then ambiguous with a limb's at 2 steps/s.  And, at a
        slow stride on the trunk, the norm's step lag together with the sway's stride lag
        (``sway_min_gyro_periodicity``).  Amplitude plays no part."""
        p = min(f["r_step"], f["r_stride"])
        if "gyro_periodicity" not in f:
            return p
        gp = f["gyro_periodicity"]
        stride = f["stride_period_s"]
        # the step lag in anti-phase is ambiguous only while twice the stride found is a walk's stride too (a trunk's
        # step); past the longest stride searched (``antiphase_in_range``) the lag found is a limb's stride
        longest = max(self.max_stride_s, self.slow_window_max_stride_s)
        if f["r_step"] >= self.step_antiphase or (self.antiphase_in_range and 2.0 * stride > longest + 1e-9):
            p = max(p, min(f["r_stride"], gp))
        sway = self.sway_min_gyro_periodicity
        if (sway is not None and gp >= sway and f["tilt_rms_rad"] < self.trunk_max_tilt_rad
                and stride >= self.slow_stride_s - 1e-9):
            # a slow walk on the trunk (``sway_min_gyro_periodicity``): the norm repeats from one foot to the other
            # (the step lag) while the trunk's sway repeats every stride
            p = max(p, min(f["r_step"], gp))
        return p

    def _periodic_gait(self, f: dict, hold: bool = False) -> float:
        """Soft evidence (0..1) that a norm too small for ``min_walk_std_m_s2`` is a walk's (issue #25): periodic at
        both legs' lags (:meth:`gait_periodicity`) above ``gentle_min_periodicity`` with a standard deviation above
        ``gentle_min_std_m_s2``, or above ``slow_min_periodicity`` with one above ``slow_min_std_m_s2``: the more the
        norm moves, the less periodicity it takes (a phone held while standing moves it by 0.1-0.3 m/s^2)."""
        p = self.gait_periodicity(f)
        std = f["acc_std_m_s2"]
        slow_stride = self._slow_stride(f)
        slow = _sig(p, self.slow_min_periodicity, 0.05) if slow_stride else 0.0
        if hold and self.slow_hold and slow_stride:
            slow = max(slow, _sig(f["periodicity"], min(self.slow_min_periodicity, self.hold_periodicity), 0.05))
        return max(_sig(p, self.gentle_min_periodicity, 0.05) * _sig(std, self.gentle_min_std_m_s2, 0.02),
                   slow * _sig(std, self.slow_min_std_m_s2, 0.05))

    def _periodic_gait_met(self, p: float, std: float, slow: bool) -> bool:
        """The hard form of :meth:`_periodic_gait`: both legs' periodicity ``p``, the norm's ``std`` (m/s^2) and
        whether the stride is a slow walk's (:meth:`_slow_stride`)."""
        return ((p >= self.gentle_min_periodicity and std >= self.gentle_min_std_m_s2)
                or (slow and p >= self.slow_min_periodicity and std >= self.slow_min_std_m_s2))

    def _slow_stride(self, f: dict) -> bool:
        """The stride found is a slow walk's (``slow_stride_s`` or longer: a cadence under 1.25 steps/s)."""
        return f["stride_period_s"] >= self.slow_stride_s - 1e-9

    def _gait_rotation(self, f: dict) -> float:
        """Soft evidence (0..1) that the rotation is a gait's (issue #25): the rotation's main axis periodic at the
        stride lag and the norm periodic, and either about one axis (a pendulum) or, spread over the axes (a hand
        swung with a twisting wrist), while the phone tilts less than ``twist_max_tilt_rad``: a rhythmic compass
        calibration is as periodic and as spread, but tilts the phone further."""
        periodic = _sig(f["gyro_periodicity"], 0.5, 0.05) * _sig(f["periodicity"], 0.5, 0.05)
        spread = 1.0 - _sig(f["tilt_rms_rad"], self.twist_max_tilt_rad, 0.03)
        if self.twist_min_gyro_periodicity is not None:  # a stride's periodicity, whatever the tilt
            spread = max(spread, _sig(f["gyro_periodicity"], self.twist_min_gyro_periodicity, 0.01))
        return periodic * max(_sig(f["gyro_axis_share"], self.swing_axis_share, 0.04), spread)

    def mode_scores(self, f: dict, walking: bool = False) -> dict:
        """Soft score of every mode (0..1) from the features (see the module docstring); ``walking``: the mode in
        force is a walking one (see ``hold_periodicity``)."""
        # waving the phone (a compass calibration) is no gait however periodic: it turns the phone through
        # far larger angles than any limb, and (gyroscope) fast about all three axes
        waving = _sig(f["tilt_rms_rad"], self.max_gait_tilt_rad, 0.05)
        if "gyro_rms_rad_s" in f:
            one_axis = _sig(f["gyro_axis_share"], self.swing_axis_share, 0.04)
            # a gait's rotation (issue #25): periodic at the stride, the norm periodic too.  Periodicity decides,
            # not the axis: a real hand twists the phone about the forearm as it swings, which spreads the
            # rotation over two axes (main-axis share 0.5-0.7) but keeps it periodic; waving is irregular
            gait_rotation = self._gait_rotation(f)
            waving = max(waving * (1.0 - gait_rotation),
                         _sig(f["gyro_rms_rad_s"], self.max_gait_rotation_rad_s, 0.3) * (1.0 - one_axis)
                         * (1.0 - gait_rotation))
        std = f["acc_std_m_s2"]
        # a walk, or a gentle one that is periodic at both legs: "still" needs a low amplitude AND no gait periodicity
        hold = walking and f.get("recent_std_m_s2", 0.0) >= self.hold_min_std_m_s2
        amplitude = max(_sig(std, self.min_walk_std_m_s2, 0.1), self._periodic_gait(f, hold))
        # a walk that goes on (issue #25): while the mode in force is a walking one and the norm still moves like a
        # walk's at the window's end (a stop leaves only a standing phone's tremor there), the norm's periodicity
        # need only be ``hold_periodicity``: at a turn or a change of pace the 4-s window's autocorrelation at the
        # stride dips to 0.2-0.35 for 2-5 s while the steps go on
        p0 = min(self.min_periodicity, self.hold_periodicity) if hold else self.min_periodicity
        walk = _sig(f["periodicity"], p0, 0.05) * amplitude * (1.0 - waving)
        # a limb: the tilt swings and the norm repeats every stride rather than every step
        ss = f["stride_share"]
        limb = (_sig(f["tilt_rms_rad"] / self.limb_tilt_rad + max(ss, 0.0) / self.limb_stride_share, 1.5, 0.12)
                * _sig(ss, self.min_limb_stride_share, 0.03))
        hand = _hand(f, self.screen_up_z)
        if self.hand_limb_min_tilt_rad is not None:
            # a phone read in the hand (screen up, pitched towards the face) that hardly tilts is held in front of the
            # body whatever the norm's stride share: a limb carrying it screen up would swing it (issue #25/#27)
            still = hand * (1.0 - _sig(f["tilt_rms_rad"], self.hand_limb_min_tilt_rad, 0.03))
            if self.hand_limb_max_swing_deg is not None and "gyro_rms_rad_s" in f:
                # ... nor swings: a hand swung with the phone upright, screen half up, turns by 40-65 deg a stride
                still *= 1.0 - _sig(self.stride_swing_deg(f), self.hand_limb_max_swing_deg, 2.0)
            limb *= 1.0 - still
        # the arm rather than the thigh: large horizontal (centripetal, tangential) acceleration, the norm's
        # stride share near 1; the gyroscope's rate adds to it
        arm_x = ss + 0.3 * f["horizontal_ratio"]
        if "gyro_rms_rad_s" in f:
            arm_x += 0.3 * min(max(f["gyro_rms_rad_s"] - self.swing_gyro_rad_s, -1.0), 1.0)
        arm = _sig(arm_x, self.arm_evidence, 0.2)
        if "gyro_rms_rad_s" in f:
            # a hand swung hard (issue #25, up to 10 rad/s): the arm's centripetal acceleration, the same at both
            # passes of the swing, makes the norm repeat every step (no stride share), but the rotation is the
            # arm's: fast, about one axis, periodic at the stride
            hard_swing = gait_rotation * _sig(f["gyro_rms_rad_s"], self.hard_swing_gyro_rad_s, 0.3)
            limb = max(limb, hard_swing)
            arm = max(arm, hard_swing)
            if self.hard_arm_gyro_rad_s is not None:  # a limb's periodic rotation faster than a thigh's (issue #25)
                hard_arm = (gait_rotation * _sig(f["gyro_rms_rad_s"], self.hard_arm_gyro_rad_s, 0.3)
                            * (1.0 - hand))
                if self.hard_arm_max_skew is not None and "gyro_skew" in f:  # a thigh's skewed rotation
                    hard_arm *= 1.0 - _sig(f["gyro_skew"], self.hard_arm_max_skew, 0.03)
                limb = max(limb, hard_arm)
                arm = max(arm, hard_arm)
            if self.thigh_min_skew is not None and "gyro_skew" in f:  # the thigh's skewed rotation is no arm's
                arm *= 1.0 - _sig(f["gyro_skew"], self.thigh_min_skew, 0.03)
        gx, gy = f["gravity_x"], f["gravity_y"]
        # at the ear: upright, the long axis inclined from the ear towards the mouth in the screen's plane
        ear = _sig(gy, self.upright_y, 0.08) * _sig(abs(gx), self.ear_incline_x, 0.05)
        trunk = 1.0 - limb
        at_ear = walk * trunk * (1.0 - hand) * ear
        swung = 0.0
        if self.ear_max_swing_deg is not None and "gyro_rms_rad_s" in f:
            # an upright phone that swings by tens of degrees per stride is a swung hand, not at the ear (the head
            # turns it by a few): the ear's score goes to the swinging hand
            swung = at_ear * _sig(self.stride_swing_deg(f), self.ear_max_swing_deg, 2.0)
            at_ear -= swung
        return {
            CARRY_HANDHELD: walk * trunk * hand,
            CARRY_EAR: at_ear,
            CARRY_BAG: walk * trunk * (1.0 - hand) * (1.0 - ear),
            CARRY_POCKET: walk * limb * (1.0 - arm),
            CARRY_SWINGING: walk * limb * arm + swung,
            CARRY_STILL: 1.0 - walk,
        }

    @staticmethod
    def stride_swing_deg(f: dict) -> float:
        """The phone's swing per stride from one window's gyroscope features ``f`` (deg; 0 without a gyroscope): the
        amplitude of a sinusoid at the stride period ``T`` (``stride_period_s``) whose RMS rate is the rotation's
        share that is about its main axis and periodic at the stride, ``sqrt(2) w T / (2 pi)`` with
        ``w = gyro_rms sqrt(gyro_axis_share * clip(gyro_periodicity, 0, 1))`` (rad/s): the autocorrelation at the
        period is the periodic part's share of the variance.  A phone at the ear turns with the head by a few
        degrees per stride; a swung hand and a thigh by tens (``ear_max_swing_deg``)."""
        if "gyro_rms_rad_s" not in f:
            return 0.0
        share = f["gyro_axis_share"] * min(max(f["gyro_periodicity"], 0.0), 1.0)
        w = f["gyro_rms_rad_s"] * math.sqrt(share)
        return math.degrees(math.sqrt(2.0) * w * f["stride_period_s"] / (2.0 * math.pi))

    @property
    def pending_mode(self) -> str | None:
        """The mode the hysteresis is waiting to switch to (the last hops' best, not yet in force), or None."""
        return self._cand

    def _hop_decision(self, t_ns: int) -> None:
        k = self._k
        w = np.concatenate([self._buf[k:], self._buf[:k]]) if k else self._buf
        f = self.compute_features(w[len(w) - self._n:])
        if self.slow_window(f, self._filled >= self._n_long) and self.slow_window_open():
            f = self.take_slow_window(f, self.compute_features(w))
        self.decide(t_ns, f)

    def take_slow_window(self, f: dict, f_long: dict) -> dict:
        """The features a hop decides on: the long window's ``f_long`` when it finds a very slow stride too
        (:meth:`slow_window`), its gait is periodic at both legs' lags (:meth:`gait_periodicity`) at least
        ``slow_window_min_periodicity`` and (``slow_window_while_still``) the mode in force is "not walking"; else
        ``f``.  Called before the hop's :meth:`decide` (it reads the mode in force); the fast path calls it too."""
        if not self.slow_window(f_long, True) or self.gait_periodicity(f_long) < self.slow_window_min_periodicity:
            return f
        if not self.slow_window_open():
            return f
        self.n_slow_window_hops += 1
        return f_long

    def slow_window_open(self) -> bool:
        """Whether a hop may take the long window's features now (``slow_window_while_still``: only while the mode
        in force is "not walking")."""
        return not (self.slow_window_while_still and self._decided and self.mode != CARRY_STILL)

    def slow_window(self, f: dict, full: bool) -> bool:
        """Whether the features ``f`` (of the ``window_s`` window, then of the long one) find a very slow walk's
        stride (``slow_window_stride_s``) with the long window (``slow_window_s``) full (``full``): a hop takes the
        long window's features when both do."""
        return (full and self._n_long > self._n and f["stride_period_s"] >= self.slow_window_stride_s - 1e-9
                and f["acc_std_m_s2"] < self.slow_window_max_std_m_s2)

    def decide(self, t_ns: int, f: dict) -> None:
        """One hop's decision from its window's features ``f`` (:meth:`compute_features`): the scores, the raw
        mode, the step period, the hysteresis and the change log.  The fast desktop path (desktop.fast.carry)
        computes the features of every hop at once and calls this for each."""
        sc = self.mode_scores(f, self._decided and self.mode != CARRY_STILL)
        self.features, self.scores = f, sc
        self.n_hops += 1
        best = max(sc, key=sc.get)
        total = sum(sc.values())
        conf = sc[best] / total if total > 1e-12 else 0.0
        self.raw_mode, self.raw_confidence = best, conf
        walking = best != CARRY_STILL
        # the step period whenever the norm is periodic, also before the mode has left "still"
        std = f["acc_std_m_s2"]
        periodic = f["periodicity"] >= self.min_periodicity and (
            std >= 0.5 * self.min_walk_std_m_s2
            or self._periodic_gait_met(self.gait_periodicity(f), std, self._slow_stride(f)))
        self.step_period_s = 0.5 * f["stride_period_s"] if periodic else math.nan
        # about one axis (a pendulum), or spread over the axes by a twisting wrist while the tilt is a swing's
        gp = f.get("gyro_periodicity", 0.0)
        self.rotation_periodic = bool(walking and gp >= 0.5
                                      and (f.get("gyro_axis_share", 0.0) >= self.swing_axis_share
                                           or f["tilt_rms_rad"] < self.twist_max_tilt_rad
                                           or (self.twist_min_gyro_periodicity is not None
                                               and gp >= self.twist_min_gyro_periodicity)))
        both = self.gait_periodicity(f)  # both legs
        self.both_periodicity = both if periodic else math.nan
        self.gait_std_m_s2 = std if periodic else math.nan
        slow = self._slow_stride(f)  # a slow walk's band reaches higher (see slow_max_std_m_s2)
        if not periodic or both < self.min_periodicity or std >= (self.slow_off_std_m_s2 if slow
                                                                   else self.min_walk_std_m_s2):
            self.gentle = False
        elif std < (self.slow_max_std_m_s2 if slow else self.gentle_max_std_m_s2) and self._periodic_gait_met(both, std, slow):
            self.gentle = True
        # a phone in a trouser pocket stands along the thigh (or on its edge): never screen up or down
        if not walking or f["stride_share"] < self.uneven_off_share or abs(f["gravity_z"]) >= self.screen_up_z:
            self.uneven = False
        elif f["stride_share"] >= self.uneven_on_share:
            self.uneven = True
        if not self._decided:
            self._decided = True
            if best != self.mode:
                self.changes.append(CarryChange(int(t_ns), self.mode, best, conf))
            self.mode, self.confidence = best, conf
            self.settling = self.settle_while_still and best == CARRY_STILL
            self._settle_walk(t_ns, True)
            return
        was_still = self.mode == CARRY_STILL
        self._decide_hysteresis(t_ns, best, conf, sc, total)
        self.settling = self.mode == CARRY_STILL and (self.settle_while_still
                                                      or (self._cand is not None and self._cand != CARRY_STILL))
        self._settle_walk(t_ns, was_still)

    def _settle_walk(self, t_ns: int, started: bool) -> None:
        """``settle_walk_s``: keep :attr:`settling` for that long after a walk's first walking decision (``started``:
        this hop's decision may be one: the first window's, or a change from ``still``), and while a change to
        another walking mode that began within it waits out its hysteresis."""
        self.settling_walk = False
        if self.settle_walk_s <= 0.0 or self.mode == CARRY_STILL:
            self._walk_start_ns = None
            return
        if started:
            self._walk_start_ns = int(t_ns)
        t0 = self._walk_start_ns
        if t0 is None:
            return
        limit = self.settle_walk_s * 1e9
        if t_ns - t0 < limit - 1e3 or (self._cand is not None and self._cand != CARRY_STILL
                                       and self._cand_ns - t0 < limit - 1e3):
            self.settling = self.settling_walk = True
        else:
            self._walk_start_ns = None

    def _decide_hysteresis(self, t_ns: int, best: str, conf: float, sc: dict, total: float) -> None:
        """A hop's raw decision ``best`` through the hysteresis (``switch_s``, ``switch_still_s``)."""
        if best == self.mode:
            self._cand = None
            self.confidence = conf
            return
        if best != self._cand:
            self._cand, self._cand_ns = best, t_ns
        need = self.switch_still_s if CARRY_STILL in (best, self.mode) else self.switch_s
        if (t_ns - self._cand_ns) * 1e-9 >= need - 1e-9:
            self.changes.append(CarryChange(int(t_ns), self.mode, best, conf))
            self.mode, self.confidence = best, conf
            self._cand = None
        else:
            self.confidence = sc[self.mode] / total if total > 1e-12 else 0.0

    # -- diagnostics -------------------------------------------------------------
    def counters(self) -> dict:
        """Time per mode (s), the changes and their number: the ``carry`` counters of a batch run."""
        return {"time_s": {m: round(v, 2) for m, v in self.time_s.items() if v > 0},
                "n_changes": len(self.changes),
                "changes": [{"t_ns": c.t_ns, "from": c.from_mode, "to": c.to_mode,
                             "confidence": round(c.confidence, 3)} for c in self.changes],
                "mode": self.mode, "confidence": round(self.confidence, 3)}


def time_in_modes(carry_counters: dict, t_start_ns: int, intervals) -> dict:
    """Seconds per mode over ``intervals`` (``[(t0_ns, t1_ns)]``) from a run's ``counters["carry"]``.

    The mode before the first change is that change's ``from`` (the current mode without changes), from
    ``t_start_ns`` on; each change holds until the next.  Used by the benchmark and the tests to compare
    the detected modes with the truth over the walking time.
    """
    changes = carry_counters.get("changes", [])
    first = changes[0]["from"] if changes else carry_counters.get("mode", CARRY_HANDHELD)
    bounds = [(int(t_start_ns), first)] + [(c["t_ns"], c["to"]) for c in changes]
    out: dict = {}
    for a, b in intervals:
        for k, (t0, mode) in enumerate(bounds):
            t1 = bounds[k + 1][0] if k + 1 < len(bounds) else b
            lo, hi = max(a, t0), min(b, t1)
            if hi > lo:
                out[mode] = out.get(mode, 0.0) + (hi - lo) * 1e-9
    return out
