"""Never lose a consistent stream (issue #26): on a simulated walk the filter has diverged (an outage in which
the phone turned in the hand: the steps' heading 45 deg off, the track about 70 m away, far beyond its covariance);
when good fixes come back the filter re-locks to them within 30 s and says so."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from core.geodesy import geodetic_to_enu

#: the outage (s of simulation time) and when the phone turns in the hand inside it
OUTAGE_S = (90.0, 90.0)
TURN_AT_S = 100.0
TURN_DEG = 45.0
SEED = 2


def _turned(steps, t_from_ns: int, angle_rad: float):
    """The pipeline's steps with the heading turned by ``angle_rad`` from ``t_from_ns`` on (positions re-integrated):
    the phone turned in the hand, which the heading model learnt before cannot know."""
    out, e, n = [], None, None
    for s in steps:
        h = s.heading_rad + (angle_rad if s.t_ns >= t_from_ns else 0.0)
        if e is None:
            e, n = s.east_m, s.north_m
        else:
            e, n = e + s.length_m * math.cos(h), n + s.length_m * math.sin(h)
        out.append(replace(s, heading_rad=h, east_m=e, north_m=n))
    return out


def diverged(seed: int = SEED, minutes: float = 4.0, multipath: bool = False):
    """The walk (the receiver without its random multipath episodes unless ``multipath``: good fixes come back), its
    pipeline steps turned from ``TURN_AT_S`` on, and the time the fixes return (ns)."""
    from core.pdr.pipeline import Pipeline
    from desktop.simulator import GpsFault, GpsModel, outdoor_walk

    gps = GpsModel(faults=(GpsFault("outage", *OUTAGE_S),)) if multipath else \
        GpsModel(multipath_per_min=0.0, faults=(GpsFault("outage", *OUTAGE_S),))
    walk = outdoor_walk(seed, minutes=minutes, rate_hz=50.0, gps=gps)
    rec = walk.recording
    clock0 = int(rec.metadata["clock_start_ns"])
    steps = _turned(Pipeline().run(rec).steps, clock0 + int(TURN_AT_S * 1e9), math.radians(TURN_DEG))
    return walk, steps, clock0 + int(sum(OUTAGE_S) * 1e9)


@pytest.fixture(scope="module")
def diverged_walk():
    return diverged()


def _error_m(walk, step) -> float:
    e, n = geodetic_to_enu(step.lat_deg, step.lon_deg, walk.truth.origin_lat_lon)
    p = walk.truth.phone_position_at(step.t_ns)
    return math.hypot(e - p[0], n - p[1])


@pytest.mark.parametrize("name", ["chen", "kubrak"])
def test_a_diverged_filter_relocks_to_good_fixes_within_30_s_and_says_so(diverged_walk, name):
    """Before: the consistent-stream rule waited ``relock_s`` of gated fixes after the judge's settling (8 fixes,
    then 10 s), so the relock came 38-40 s after the fixes returned, the track 70-80 m off meanwhile."""
    from core.gnss import make_fusion

    walk, steps, back_ns = diverged_walk
    rec = walk.recording
    fr = make_fusion(name).run(steps, rec.streams["gps"], rec.t0_ns)
    ts = np.array([s.t_ns for s in fr.steps])
    before = fr.steps[int(np.searchsorted(ts, back_ns))]
    assert _error_m(walk, before) > 30.0  # diverged: the scenario holds
    relocks = [r for r in fr.counters["relocks"] if r["t_ns"] >= back_ns]
    assert relocks and relocks[0]["rule"] == "consistent stream", relocks
    r = relocks[0]
    assert r["t_ns"] - back_ns <= 30e9, (r["t_ns"] - back_ns) * 1e-9
    assert r["offset_m"] > 30.0 and 20.0 <= r["consistent_s"] <= 30.0  # says how far off, and on what evidence
    after = fr.steps[int(np.searchsorted(ts, r["t_ns"] + 10e9))]
    assert _error_m(walk, after) < 10.0
    # how far GPS moved the track, by kind (diagnostics as data): the relock's jump is its offset, the largest of the
    # walk; every other accepted fix but the anchor is an ordinary update
    moves = fr.counters["gps_moves"]
    by = moves["by_kind"]
    n_cs = sum(x["rule"] == "consistent stream" for x in fr.counters["relocks"])
    assert by["relock (consistent stream)"]["n"] == n_cs
    assert moves["largest"]["kind"] == "relock (consistent stream)" and moves["largest"]["moved_m"] > 30.0
    assert any(abs(x["offset_m"] - moves["largest"]["moved_m"]) < 1e-6 for x in relocks)
    assert sum(v["n"] for v in by.values()) == sum(f.accepted for f in fr.fixes) - 1  # the anchor moves nothing
    assert by["update"]["moved_m"] == pytest.approx(sum(f.correction_m for f in fr.fixes if f.accepted) -
                                                    sum(v["moved_m"] for k, v in by.items() if k != "update"))
    assert moves["first"]["kind"] == "update" and moves["first"]["sigma_before_m"] > 0.0


def test_kubrak_relock_puts_the_track_on_the_fix_not_beside_it_by_a_stale_bias():
    """A consistent-stream restart moves the position by the innovation, which includes the bias states' estimate;
    the bias a drifting track built up against the fixes must not stay (before: the track ran 6-10 m beside the
    fixes for minutes after a relock on the tuning walk).  Afterwards the predicted fix is the fix, the position's
    variance is the fix's white plus correlated error, and the covariance stays one."""
    from core.gnss.kubrak import BE, BN, KubrakKf

    kf = KubrakKf()
    kf.initialize(0.0, 0.0, 2.0)
    st = kf.snapshot()
    st.x[BE], st.x[BN] = 6.0, -4.0  # what the bias states absorbed while the track drifted
    st.P[BE, BE] = st.P[BN, BN] = 0.5 ** 2
    kf.restore(st)
    fix, sigma = np.array([40.0, 25.0]), 3.0
    pred, _ = kf.fix_prediction(0)
    kf.restart_position(fix - pred, sigma)
    kf.place_on_fix(sigma)
    assert kf.x[:2] == pytest.approx(fix) and kf.x[BE:BN + 1] == pytest.approx([0.0, 0.0])
    assert kf.fix_prediction(0)[0] == pytest.approx(fix)
    assert kf.P[0, 0] == pytest.approx(sigma ** 2 + kf.fix_bias_sd_m ** 2)
    assert np.linalg.eigvalsh(0.5 * (kf.P + kf.P.T)).min() >= -1e-9


def test_chen_learns_the_new_grip_and_stays_on_the_fixes_after_taking_them_back():
    """Issue #26: on the 7-minute walk (seed 1, the receiver's multipath on) Chen's filter takes the fixes back 20 s
    after the outage, its EKF heading follows them, but the heading model's outlier gate rejected the windows that
    showed the phone's new grip (45 deg): when the judge then refused the fixes (the steps disagree with them by
    that angle) the step headings pulled the filter back to the old offset and the track ran 20-80 m off for three
    minutes (before: 28 m at 70 s, 63 m at 120 s after the fixes returned).  Now the model learns the new grip
    from two windows that agree, and the track stays within 10 m while the stream is clean."""
    from core.gnss import make_fusion

    walk, steps, back_ns = diverged(seed=1, minutes=7.0, multipath=True)
    rec = walk.recording
    fusion = make_fusion("chen")
    fr = fusion.run(steps, rec.streams["gps"], rec.t0_ns)
    ts = np.array([s.t_ns for s in fr.steps])
    # from 40 s after the fixes return until a multipath episode at +170 s (the fixes 24 m off: a relock follows)
    errs = [_error_m(walk, fr.steps[int(np.searchsorted(ts, back_ns + dt * 1e9))]) for dt in range(40, 161, 10)]
    assert max(errs) < 10.0, [round(e, 1) for e in errs]
    assert fusion.heading_model.n_regrips >= 1  # said so (training counters: heading_model.new_grips)
    assert fr.counters["training"]["heading_model"]["new_grips"] >= 1


def _rescaled(steps, factor: float):
    """The pipeline's steps with every length times ``factor`` (positions re-integrated): a stride model or step count
    that is that far off."""
    out, e, n = [], None, None
    for s in steps:
        length = s.length_m * factor
        if e is None:
            e, n = s.east_m, s.north_m
        else:
            e, n = e + length * math.cos(s.heading_rad), n + length * math.sin(s.heading_rad)
        out.append(replace(s, length_m=length, east_m=e, north_m=n))
    return out


@pytest.mark.parametrize("name, factor, cause", [("chen", 2.4, "receiver's speed"),
                                                 ("kubrak", 0.4, "inconsistent with the steps")])
def test_good_fixes_the_steps_scale_refuses_are_taken_as_a_consistent_stream_and_said(diverged_walk, name, factor,
                                                                                       cause):
    """Never lose a consistent stream (issue #26, the stream lock): the same walk with the steps 2.4x too long (the
    pace check then says the receiver sees under half the walk) or 0.4x (the shape test's 0.7-1.4 scale band
    fails).  The judge compares the fixes with the pipeline's own steps, whose stride the fusion never corrects, so
    before the lock the good fixes were refused for most of the walk (2.4x: 1 of 147 fixes taken, 147 s lost besides
    the 90-s outage, the track 301 m off at the end; 0.4x: 19 taken, 83 s lost).  Now the fixes, agreeing among
    themselves and with the walker's turns at a walking pace for 30 s, are taken within 60 s of the walk's start
    and of the outage's end (35 s), the track ends within 10 m, and the summary says so."""
    from core.gnss import make_fusion
    from core.gnss.judge import verdict_text

    walk, steps, back_ns = diverged_walk
    rec = walk.recording
    gps = rec.streams["gps"]
    fr = make_fusion(name).run(_rescaled(steps, factor), gps, rec.t0_ns)
    taken = np.array([f.t_ns for f in fr.fixes if f.accepted])
    outage = (rec.t0_ns + int(OUTAGE_S[0] * 1e9), back_ns)
    bounds = np.concatenate([[gps.t_ns[0]], taken, [gps.t_ns[-1]]])
    lost = [(b - a) * 1e-9 - ((outage[1] - outage[0]) * 1e-9 if a <= outage[0] and b >= outage[1] else 0.0)
            for a, b in zip(bounds[:-1], bounds[1:])]
    assert max(lost) <= 60.0, max(lost)
    assert _error_m(walk, fr.steps[-1]) < 10.0
    j = fr.counters["gps_judge"]
    assert j["fixes_locked"] >= 20 and any(cause in c for c in j["locked_over"]), j["locked_over"]
    assert "taken as a consistent stream" in verdict_text(j, name)
