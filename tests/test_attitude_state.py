"""AttitudeEKF's typed state: made only by AttitudeState.initial, read and set only through snapshot/restore."""

import collections
import dataclasses
import enum
import math

import numpy as np
import pytest

from core import quaternion as quat
from core.pdr.attitude import AttitudeEKF, AttitudeState, IntervalSum, Outcome


def _events(seconds=12.0, rate_hz=100.0, seed=3):
    """A phone turning slowly on a table, then waved (acc, gyro, mag at 50 Hz), in time order."""
    rng = np.random.default_rng(seed)
    out = []
    n = int(seconds * rate_hz)
    for k in range(n):
        t = 1_000_000_000 + int(k * 1e9 / rate_hz)
        wz = 0.3 * math.sin(0.5 * k / rate_hz) if k > n // 2 else 0.0
        yaw = 0.6 * (1 - math.cos(0.5 * k / rate_hz)) if k > n // 2 else 0.0
        out.append(("gyro", t, (rng.normal(0, 0.003), rng.normal(0, 0.003), wz + rng.normal(0, 0.003))))
        out.append(("acc", t + 1000, tuple(np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.05, 3))))
        if k % 2 == 0:
            c, s = math.cos(yaw), math.sin(yaw)
            m = np.array([20.0 * s, 20.0 * c, -44.0]) + rng.normal(0, 0.4, 3)  # the field seen by a turned phone
            out.append(("mag", t + 2000, tuple(m)))
    return out


def _feed(ekf, events):
    handlers = {"gyro": ekf.predict, "acc": ekf.update_acc, "mag": ekf.update_mag}
    for name, t, v in events:
        handlers[name](t, *v)


def _plain(x):
    """A comparable form of a state: dataclasses, objects and containers taken apart, nan equal to nan."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__, {f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x)})
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, collections.deque)):
        return [_plain(v) for v in x]
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if isinstance(x, enum.Enum):
        return x
    if isinstance(x, np.floating):
        return _plain(float(x))
    slots = [n for c in type(x).__mro__ for n in getattr(c, "__slots__", ())]
    if hasattr(x, "__dict__") or slots:
        attrs = dict(getattr(x, "__dict__", {}))
        attrs.update({n: getattr(x, n) for n in slots if hasattr(x, n)})
        return (type(x).__name__, _plain(attrs))
    return x


def test_reset_gives_what_a_new_filter_has():
    ekf = AttitudeEKF()
    _feed(ekf, _events())
    assert ekf.initialized and ekf.n_mag_used > 0
    assert _plain(ekf.snapshot()) != _plain(AttitudeEKF().snapshot())
    ekf.reset()
    new = AttitudeEKF()
    assert vars(ekf).keys() == vars(new).keys()  # no attribute born outside reset()
    assert _plain(ekf.snapshot()) == _plain(new.snapshot())
    assert type(ekf.snapshot()) is AttitudeState


def test_the_filter_keeps_no_state_outside_its_state_object():
    ekf = AttitudeEKF()
    _feed(ekf, _events(seconds=4.0))
    # besides the state: configuration, and the replay's history (issue #27: written by the filter, never read by it;
    # None unless keep_history, and the state is the same with it: tests/test_heading_smoother.py), and matrix()'s
    # cache (_R of the quaternion object _R_q: a function of the state's q, never state)
    assert set(vars(ekf)) == {"settings", "mag_calibrator", "field_detector", "_state", "keep_history", "start_heading",
                              "history", "_R_q", "_R"}
    assert ekf._R_q is None or ekf._R == quat.to_matrix(ekf._R_q)
    assert ekf.history is None and ekf.start_heading is None
    snap = ekf.snapshot()
    with pytest.raises(AttributeError):  # slots: a misspelt field cannot be born on the state
        snap.acc_sums = IntervalSum.empty()


def test_snapshot_and_restore_continue_the_same_filter_exactly():
    ev = _events()
    half = len(ev) // 2
    a = AttitudeEKF()
    _feed(a, ev[:half])
    snap = a.snapshot()
    _feed(a, ev[half:])
    b = AttitudeEKF()
    b.restore(snap)
    _feed(b, ev[half:])
    assert b.q == a.q and b.b == a.b and np.array_equal(b.P, a.P)
    assert _plain(b.snapshot()) == _plain(a.snapshot())


def test_a_snapshot_is_a_copy_both_ways():
    ekf = AttitudeEKF()
    _feed(ekf, _events(seconds=4.0))
    q0 = ekf.q
    snap = ekf.snapshot()
    snap.q = (0.0, 1.0, 0.0, 0.0)
    n_gated = len(snap.gated)
    snap.gated.append((0, 0.0))
    assert ekf.q == q0 and len(ekf.snapshot().gated) == n_gated
    ekf.restore(snap)
    snap.q = (1.0, 0.0, 0.0, 0.0)
    assert ekf.q == (0.0, 1.0, 0.0, 0.0)
    with pytest.raises(TypeError):
        ekf.restore(vars(snap) if hasattr(snap, "__dict__") else {})


def test_the_fast_path_fails_at_import_on_a_field_it_does_not_know():
    """desktop.fast.attitude checks its slot tables against the dataclasses' fields (a new field fails there)."""
    from desktop.fast import attitude as fatt

    grown = dataclasses.make_dataclass("GrownState", [("new_counter", int)], bases=(AttitudeState,), slots=True)
    with pytest.raises(ImportError, match="new_counter"):
        fatt._check_covered(grown, fatt.STATE_USE)
    fatt._check_covered(AttitudeState, fatt.STATE_USE)  # and today's passes
    # the slot numbers follow the fields: every float state slot is a field (or one of its parts)
    names = {f.name for f in dataclasses.fields(AttitudeState)}
    assert all(k.split(".")[0] in names for k in fatt.FS)


def test_every_reading_is_counted_under_an_outcome():
    ev = _events(seconds=6.0)
    ekf = AttitudeEKF()
    _feed(ekf, ev)
    for kind, reasons, last in (("acc", ekf.acc_reasons, ekf.last_acc), ("mag", ekf.mag_reasons, ekf.last_mag)):
        assert sum(reasons.values()) == sum(1 for e in ev if e[0] == kind)
        assert {Outcome(k) for k in reasons} >= {Outcome.USED, Outcome.INITIALISING}
        assert isinstance(last.outcome, Outcome) and last.reason.startswith(last.outcome.value)
