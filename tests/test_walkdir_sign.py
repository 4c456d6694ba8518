"""The walking direction's sign from a limb's swing (core.pdr.walkdir ``sign_method``, issue #25 section 3).

A phone on a limb (a trouser pocket, a hand at the side) is swung forward fast and brought back slowly: its
horizontal velocity along the walk is skewed forward, whatever the trunk's pendulum does.  The synthetic
limb here has the trunk's phase relation reversed (as the real tuning walk ``thomasdingemanse_lopen`` shows
it: the phase rule took 98 % of its strides backwards), so the phase rule gets the sign wrong and the skew
rule right; on the trunk (the phase rule's own gait) ``auto`` keeps the phase rule.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from core import quaternion as quat
from core.conventions import STANDARD_GRAVITY_M_S2, wrap_angle
from core.pdr.walkdir import SIGN_METHODS, WalkingDirection, _AxisState
from test_walkdir import RATE_HZ, STEP_HZ, _feed


def _limb_velocity(t: float, v_m_s: float = 0.8, swing_share: float = 0.4) -> float:
    """Forward velocity of the phone relative to the walker over a stride: a fast swing, a slow return."""
    phi = (t * 0.5 * STEP_HZ) % 1.0
    if phi < swing_share:
        return v_m_s * math.sin(math.pi * phi / swing_share)
    return -v_m_s * swing_share / (1.0 - swing_share) * math.sin(math.pi * (phi - swing_share) / (1.0 - swing_share))


def _feed_limb(wd: WalkingDirection, *, offset_deg: float, seconds: float = 40.0, heading_deg: float = 30.0,
               trunk_reversed_m_s2: float = 0.6, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    w = 2.0 * math.pi * STEP_HZ
    dt = 1.0 / RATE_HZ
    h = math.radians(heading_deg)
    dev = h - math.radians(offset_deg)
    q = quat.from_axis_angle((0.0, 0.0, 1.0), dev - 0.5 * math.pi)
    r = quat.to_matrix(q)
    out = []
    for k in range(int(seconds * RATE_HZ)):
        t = k * dt
        a_f = (_limb_velocity(t + dt) - _limb_velocity(t)) / dt + trunk_reversed_m_s2 * math.sin(w * t)
        a_up = 0.03 * w * w * math.cos(w * t)
        a_n = (a_f * math.cos(h), a_f * math.sin(h), a_up)
        a_n = [a + 0.05 * rng.standard_normal() for a in a_n]
        f = (a_n[0], a_n[1], a_n[2] + STANDARD_GRAVITY_M_S2)
        acc_b = [r[0][i] * f[0] + r[1][i] * f[1] + r[2][i] * f[2] for i in range(3)]
        step = k % int(round(RATE_HZ / STEP_HZ)) == 0 and t > 0.5
        wd.update(10**12 + int(t * 1e9), q, *acc_b, math.cos(dev), math.sin(dev), step, (0.0, 1.0, 0.0))
        out.append(wd.offset_rad)
    return out


@pytest.mark.parametrize("offset_deg", [0.0, 75.0, -140.0])
def test_limb_swing_sign(offset_deg):
    want = math.radians(offset_deg)
    got = {}
    for sm in SIGN_METHODS:
        wd = WalkingDirection(grid_rate_hz=RATE_HZ, delay_s=0.0, sign_method=sm)
        _feed_limb(wd, offset_deg=offset_deg)
        assert wd.n_accepted > 20
        got[sm] = math.degrees(abs(wrap_angle(wd.offset_rad - want)))
        if sm != "phase":
            assert all("skew" in s for s in wd.strides if s["accepted"])
    assert got["phase"] > 170.0  # the trunk's rule, reversed on this limb: backwards
    assert got["skew"] < 5.0 and got["auto"] < 5.0
    wd = WalkingDirection(grid_rate_hz=RATE_HZ, delay_s=0.0, sign_method="auto")
    _feed_limb(wd, offset_deg=offset_deg)
    assert sum(s.get("method") == "pca" for s in wd.strides if s["accepted"]) > 0.9 * wd.n_accepted


def test_auto_keeps_the_phase_rule_on_the_trunk():
    """The trunk gait of tests/test_walkdir.py (lateral sway: the coherent axis): ``auto`` = ``phase`` bit for bit."""
    offs = {}
    for sm in ("phase", "auto"):
        wd = WalkingDirection(grid_rate_hz=RATE_HZ, delay_s=0.45, sign_method=sm)
        offs[sm] = _feed(wd, offset_deg=60.0, seconds=30.0)
        assert abs(math.degrees(wrap_angle(wd.offset_rad - math.radians(60.0)))) < 5.0
    assert offs["phase"] == offs["auto"]


def test_sign_method_checked_and_no_nan():
    with pytest.raises(ValueError, match="sign_method"):
        WalkingDirection(sign_method="vote")
    wd = WalkingDirection(grid_rate_hz=RATE_HZ, sign_method="auto")
    q = (1.0, 0.0, 0.0, 0.0)
    for k in range(500):  # standing still, then non-finite samples: the skew stays finite, no stride accepted
        wd.update(k * 20_000_000, q, 0.0, 0.0, STANDARD_GRAVITY_M_S2 if k % 7 else math.nan, 0.0, 1.0, k % 25 == 0)
    assert wd.n_accepted == 0 and math.isfinite(wd.offset_rad) and wd.n_nonfinite > 0
    assert math.isfinite(wd._skew_along(0.3))


def _strides(wd: WalkingDirection, pattern: str, truth: float = 0.3, seed: int = 1, skew=None) -> list:
    """Accepted strides fed at the stride level (``_accumulate``), as on the real tuning walk
    ``thomasdingemanse_lopen``: a limb whose raw-axis strides (``"p"``) have the forward skew (+0.15) and
    whose other strides (``"c"``, the coherent axis, 25 deg to one side) carry the trunk's phase evidence,
    reversed on a limb (-0.3 along the walk).  ``skew``: each stride's skew evidence (default 0.15).  Returns the
    offset after each stride."""
    rng = np.random.default_rng(seed)
    st = _AxisState()
    out = []
    for i, ch in enumerate(pattern):
        raw_axis = truth + math.radians(3.0) * rng.standard_normal()
        theta = raw_axis if ch == "p" else truth + math.radians(25.0)
        g = -0.3  # the phase rule's evidence along the walk: backwards on this limb
        kev = 0.15 if skew is None else skew[i]
        wd._accumulate(st, theta, g * math.cos(theta), g * math.sin(theta), kev, ch == "p", raw_axis)
        st.n += 1
        out.append(wd._offset_of(st))
    return out


def test_one_limb_decision_per_placement():
    """A limb whose share of raw-axis strides hovers about a half (the lopen walk: 0.43-0.83 over a minute)
    keeps its sign: the per-stride majority rule of the skew sign flipped the whole estimate backwards each
    time the share dipped below a half (groups of 2-8 steps walked backwards on the real walk); the placement's
    raw axis also removes the coherent strides' sideways pull."""
    pattern = "pppppppppp" + "ccpcpcpccpcpccppcpcc" * 4  # the share of "p" falls from 1 to about 0.45
    old = WalkingDirection(sign_method="auto", limb_exit_share=0.5, limb_raw_axis=False, limb_sign_margin=0.0)
    new = WalkingDirection(sign_method="auto")
    err_old = np.degrees(np.abs([wrap_angle(o - 0.3) for o in _strides(old, pattern)]))
    err_new = np.degrees(np.abs([wrap_angle(o - 0.3) for o in _strides(new, pattern)]))
    assert np.max(err_old) > 150.0  # the rule before: backwards while the share is below a half
    assert np.max(err_new[10:]) < 5.0  # one decision: forward throughout, on the raw axis
    with pytest.raises(ValueError, match="limb_exit_share"):
        WalkingDirection(limb_enter_share=0.3, limb_exit_share=0.5)


def test_axis_state_values_round_trip():
    st = _AxisState()
    for i, k in enumerate(_AxisState.FIELDS):
        setattr(st, k, 0.5 + i)
    st.n = 7
    back = _AxisState.from_values(st.values(), st.n)
    assert back.values() == st.values() and back.n == 7
    part = _AxisState.from_values(st.values()[:6], 3)  # the fast kernel's rows: the phase rule's six
    assert part.values()[:6] == st.values()[:6] and part.kx == part.limb == 0.0


def test_limb_sign_holds_through_a_dip_of_the_skew():
    """A limb's per-stride skew is a weak, noisy cue (right on 76 % of the lopen walk's strides; its remembered
    mean near +0.05 and dipping to -0.05 at 37-45 s and 71 s, where the steps went backwards): the direction
    holds until the evidence is clearly against it, and still turns when it is (the phone turned round)."""
    rng = np.random.default_rng(3)
    n = 120
    skew = 0.08 + 0.3 * rng.standard_normal(n)
    skew[40:48] = -0.25  # a dip: the mean evidence falls just below zero
    skew[80:] = -0.4  # the phone turned round: clearly backwards from here on
    skew = np.clip(skew, -1.0, 1.0)
    errs = {}
    for margin in (0.0, 0.1):
        wd = WalkingDirection(sign_method="auto", limb_sign_margin=margin)
        offs = _strides(wd, "p" * n, skew=skew)
        errs[margin] = np.degrees(np.abs([wrap_angle(o - 0.3) for o in offs]))
    assert np.max(errs[0.0][10:80]) > 150.0  # stride by stride: backwards in the dip
    assert np.max(errs[0.1][10:80]) < 10.0  # held
    assert np.all(errs[0.1][95:] > 170.0) and np.all(errs[0.0][95:] > 170.0)  # both follow a real turn
