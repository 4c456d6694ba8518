"""ZuptEKF's typed state (core.foot.ins.InsState): made only by InsState.initial, in and out only through
snapshot/restore; FootNavigator sets every attribute in reset()."""

import dataclasses
import math

import numpy as np
import pytest

from core.foot.ins import InsState, ZuptEKF
from core.foot.navigator import FootNavigator, FootSettings
from desktop.foot_simulator import footprints, simulate_foot
from tests._state_helpers import differences, scalar_attributes


def _walk():
    """A short noisy walk at 100 Hz (three strides, a quarter turn)."""
    w = simulate_foot(footprints([(2.8, 0.0), (1.4, math.pi / 2)]), rate_hz=100.0, acc_noise_m_s2=0.05,
                      gyro_noise_rad_s=0.005, gyro_bias_rad_s=(0.002, -0.001, 0.003), first_still_s=1.0, seed=11)
    return w


class _Run:
    """Drives a ZuptEKF through the walk's samples (true stance): ZUPT, ZARU, and at each stance's end a
    heading measurement relative to the previous stance's (the consider term), as the navigator does."""

    def __init__(self, w):
        self.w = w
        still = w.t_ns < w.t_ns[0] + 900_000_000
        self.acc_mean, self.gyro_mean = w.acc_b[still].mean(axis=0), w.gyro_b[still].mean(axis=0)
        self.k0 = int(np.sum(still))

    def steps(self, ekf: ZuptEKF, k_from: int, k_to: int) -> list:
        w, out = self.w, []
        for k in range(k_from, k_to):
            acc, gyro = tuple(w.acc_b[k]), tuple(w.gyro_b[k])
            ekf.propagate(acc, gyro, (w.t_ns[k] - w.t_ns[k - 1]) * 1e-9)
            if w.stance[k]:
                ekf.update_zero_velocity(1.0, gyro)
                ekf.update_zero_rate(gyro)
                if k + 1 < len(w.t_ns) and not w.stance[k + 1]:  # the stance's last sample
                    h = (0.0, 0.0, 1.0)
                    ekf.update_heading_relative(0.01, h, 1e-4)
                    ekf.consider_heading(h)
            out.append(ekf.p + ekf.v + ekf.q + (ekf.horizontal_position_sd_m(),))
        return out


def test_ins_reset_is_a_new_filter():
    """After a run (history kept, consider term set, caches filled), reset() leaves every attribute as a new
    filter's; before it, ZuptEKF had no reset()."""
    w = _walk()
    run = _Run(w)
    ekf = ZuptEKF(zupt_lever_up_m=0.05)
    ekf.keep_history()
    ekf.align(run.acc_mean, run.gyro_mean)
    run.steps(ekf, run.k0, len(w.t_ns))
    new = ZuptEKF(ekf.settings)
    assert differences(ekf.snapshot(), new.snapshot())
    ekf.reset()
    assert vars(ekf).keys() == vars(new).keys()
    differ = [k for k in vars(new) if differences(vars(ekf)[k], vars(new)[k])]
    assert differ == [], differ
    assert [f.name for f in dataclasses.fields(InsState)] == list(InsState.__slots__)


def test_ins_snapshot_restore_continues_bit_identically():
    """Snapshot mid-walk, restore into a new filter, run on: the same track, bit for bit, as one uninterrupted
    run (all caches cold in the new filter); the snapshot is a copy both ways."""
    w = _walk()
    run = _Run(w)
    settings = ZuptEKF(zupt_lever_up_m=0.05, zupt_rate_lever_m=0.03).settings
    whole = ZuptEKF(settings)
    whole.align(run.acc_mean, run.gyro_mean)
    track = run.steps(whole, run.k0, len(w.t_ns))
    ends = [k for k in range(run.k0, len(w.t_ns) - 1) if w.stance[k] and not w.stance[k + 1]]
    mid = ends[1] + 10  # in the second swing: the consider term is set
    assert not w.stance[mid] and len(ends) >= 3
    first = ZuptEKF(settings)
    first.align(run.acc_mean, run.gyro_mean)
    head = run.steps(first, run.k0, mid)
    snap = first.snapshot()
    assert snap.consider is not None
    second = ZuptEKF(settings)
    second.restore(snap)
    snap.P[:] = np.nan  # the filter took a copy
    tail = run.steps(second, mid, len(w.t_ns))
    assert head + tail == track
    assert first.snapshot().P is not first.snapshot().P  # ... and hands out copies
    with pytest.raises(TypeError):
        second.restore(dataclasses.asdict(snap))
    second.keep_history()  # a filter that keeps the smoother's history refuses (two runs would mix) ...
    with pytest.raises(ValueError):
        second.restore(snap)
    with pytest.raises(ValueError):  # ... and its covariance is read only from outside
        second.P[0, 0] = 1.0


def test_navigator_reset_sets_every_attribute():
    """FootNavigator.reset() sets every attribute (none is born in _sample or _align_step), with the same
    type as a new navigator's, and the INS's state is a new one's."""
    w = _walk()
    nav = FootNavigator(FootSettings(initial_heading_rad=-math.pi / 2, rts_smoother=False))
    nav.run(w.recording, stance=w.stance)
    new = FootNavigator(nav.settings)
    nav.reset()
    assert vars(nav).keys() == vars(new).keys(), set(vars(nav)) ^ set(vars(new))
    assert {k: type(v) for k, v in vars(nav).items()} == {k: type(v) for k, v in vars(new).items()}
    assert not differences(nav.ins.snapshot(), new.ins.snapshot())
    assert scalar_attributes(nav) == scalar_attributes(new)  # plain values as a new one's (nan equal to nan)
    # ... and its values: the reset navigator walks the same walk again to the same track as a new one
    a, b = nav.run(w.recording, stance=w.stance), new.run(w.recording, stance=w.stance)
    assert np.array_equal(a.position_n, b.position_n, equal_nan=True) and a.counters == b.counters
