"""The GPS filters' typed state (PdrEkf, KubrakKf): made only by ``State.initial``, read and set only through
``snapshot`` / ``restore``; ``reset()`` forgets all of it, and a restored filter goes on exactly as the original."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from core.gnss.ekf import PdrEkf, PdrEkfState
from core.gnss.kubrak import COEF, KubrakKf, KubrakKfState


def _same(a, b) -> bool:
    """Two states equal field by field, bit for bit (arrays by their bytes, nan equal to nan)."""
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        u, v = getattr(a, f.name), getattr(b, f.name)
        if isinstance(u, np.ndarray) or isinstance(v, np.ndarray):
            if not (isinstance(u, np.ndarray) and isinstance(v, np.ndarray) and u.shape == v.shape
                    and u.tobytes() == v.tobytes()):
                return False
        elif not (u == v or (isinstance(u, float) and isinstance(v, float) and math.isnan(u) and math.isnan(v))):
            return False
    return True


def _pdr_events(seed: int = 5, n: int = 40) -> list:
    """Steps along a turning path with a fix every fourth step, a course every eighth, a relock-like restart."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        out.append(("step", 0.7 + rng.normal(0, 0.05), 0.02 * k + rng.normal(0, 0.05)))
        if k % 4 == 3:
            out.append(("fix", 0.5 * k + rng.normal(0, 2.0), 0.1 * k + rng.normal(0, 2.0), 3.0 + rng.uniform(0, 2)))
        if k % 8 == 7:
            out.append(("course", 0.02 * k + rng.normal(0, 0.1)))
        if k == 21:
            out.append(("restart", (rng.normal(0, 3.0), rng.normal(0, 3.0)), 4.0))
    return out


def _feed_pdr(ekf: PdrEkf, events) -> None:
    for ev in events:
        if ev[0] == "step":
            ekf.set_consider_sd(math.radians(5.0), 0.03)
            ekf.step(ev[1], ev[2])
        elif ev[0] == "fix":
            ekf.propagate_fix_bias(1.0, ev[3])
            ekf.update_position(ev[1], ev[2], ev[3], 0.4)
        elif ev[0] == "course":
            ekf.update_course(ev[1], math.radians(8.0))
        else:
            ekf.restart_position(ev[1], ev[2])
            ekf.place_on_fix(ev[2])


def _kubrak_events(seed: int = 6, n: int = 40) -> list:
    """Epochs of a walker speeding up, with fixes, velocities, an alignment, a revert and a relock."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        t = int(1e9 + k * 0.55e9)
        reg = (9.9 + rng.normal(0, 0.2), 1.8 + 0.005 * k, 1.4 + rng.normal(0, 0.1))
        out.append(("epoch", t, 0.55, reg, 0.3 + rng.normal(0, 0.05)))
        if k % 3 == 2:
            out.append(("fix", t + int(0.2e9), 0.7 * k + rng.normal(0, 2.0), 0.2 * k + rng.normal(0, 2.0), 3.0))
            out.append(("velocity", 1.3 + rng.normal(0, 0.1), 0.3 + rng.normal(0, 0.1)))
        if k == 10:
            out.append(("align", 0.2, 0.1))
        if k == 20:
            out.append(("revert", (0.05, 0.4, 0.1), np.diag([1e-4, 4e-3, 1e-3])))
        if k == 25:
            out.append(("relock", (rng.normal(0, 4.0), rng.normal(0, 4.0)), 3.0))
    return out


def _feed_kubrak(kf: KubrakKf, events) -> None:
    for ev in events:
        if ev[0] == "epoch":
            kf.epoch(ev[1], ev[2], ev[3], ev[4])
        elif ev[0] == "fix":
            kf.update_position(ev[1], ev[2], ev[3], ev[4])
        elif ev[0] == "velocity":
            kf.update_velocity(ev[1], ev[2], 0.3)
        elif ev[0] == "align":
            kf.align_heading(ev[1], ev[2])
        elif ev[0] == "revert":
            kf.revert_coefficients(np.array(ev[1]), ev[2], True)
        else:
            kf.restart_position(ev[1], ev[2])
            kf.place_on_fix(ev[2])
            kf.widen_heading(0.3)


def _pdr() -> PdrEkf:
    ekf = PdrEkf(fix_bias_share=0.5)  # both covariances and both fix-error processes in use
    ekf.initialize(0.0, 0.0, 2.0, 0.7, 0.0)
    return ekf


def _kubrak() -> KubrakKf:
    kf = KubrakKf()
    kf.initialize(0.0, 0.0, 2.0)
    return kf


@pytest.mark.parametrize("make,feed,events,state", [(_pdr, _feed_pdr, _pdr_events, PdrEkfState),
                                                    (_kubrak, _feed_kubrak, _kubrak_events, KubrakKfState)])
def test_reset_leaves_the_state_of_a_new_filter_and_no_other_attribute(make, feed, events, state):
    """After a run, ``reset()`` gives what a new filter has (``State.initial``), and the run added no attribute
    beside the settings and the state (no state born outside ``reset()``)."""
    f = make()
    new = type(f)(**({"fix_bias_share": 0.5} if isinstance(f, PdrEkf) else {}))
    settings = set(vars(new))
    feed(f, events())
    assert set(vars(f)) == settings
    assert not _same(f.snapshot(), new.snapshot())  # the run changed it (the test can fail)
    f.reset()
    assert _same(f.snapshot(), new.snapshot()) and _same(f.snapshot(), state.initial())
    assert set(vars(f)) == settings


@pytest.mark.parametrize("make,feed,events", [(_pdr, _feed_pdr, _pdr_events), (_kubrak, _feed_kubrak, _kubrak_events)])
def test_snapshot_restore_continue_equals_the_uninterrupted_run(make, feed, events):
    """Half a run, a snapshot, the other half: a second filter restored from the snapshot ends bit for bit where
    the uninterrupted one does; the snapshot is a copy (the run goes on without changing it)."""
    ev = events()
    half = len(ev) // 2
    a = make()
    feed(a, ev[:half])
    snap = a.snapshot()
    keep = a.snapshot()
    feed(a, ev[half:])
    assert _same(snap, keep)  # a's run did not reach into the snapshot
    b = make()
    b.reset()
    b.restore(snap)
    feed(b, ev[half:])
    assert _same(a.snapshot(), b.snapshot())
    assert not _same(a.snapshot(), keep)
    with pytest.raises(TypeError):
        b.restore(dataclasses.asdict(snap))


def test_the_gps_filters_state_is_read_only_from_outside():
    """``x`` and ``P`` are views: set the state through the filter's methods or restore()."""
    for f in (_pdr(), _kubrak()):
        with pytest.raises(AttributeError):
            f.x = np.zeros(3)
        with pytest.raises(AttributeError):
            f.P = np.eye(3)
        for arr in (f.x, f.P):  # nor written in place through the views
            with pytest.raises(ValueError):
                arr[0] = 1.0
    kf = _kubrak()
    kf.revert_coefficients(np.array([0.1, 0.2, 0.3]), np.eye(3) * 1e-3, False)
    assert kf.x[COEF].tolist() == [0.1, 0.2, 0.3] and kf.P[COEF, COEF].tolist() == (np.eye(3) * 1e-3).tolist()
