"""A live GPS fusion holds the same bytes however long the walk (issue #30).

Before: the fusion kept every fused step and fix record in lists (about 560 bytes a step and 500 a fix:
5.3 MB an hour of walking with GPS).  With ``keep_history=False`` (the app's) they go to a record file
on disk, read back for the exports; a batch run (``keep_history=True``, the default) keeps them all.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.long_walk import deep_bytes
from core.export import RecordFile
from core.geodesy import enu_to_geodetic
from core.gnss import make_fusion
from core.gnss.base import FixRecord, FusedStep, FusedTrack
from core.pdr.pipeline import Step
from core.pdr.stride import StepFeatures

ORIGIN = (60.17, 24.94)
T0 = 10 ** 12


def _walk(n_steps: int, seed: int = 3):
    """Steps (0.7 m at 0.55 s) round a 60 m square, and 1-Hz fixes of the true position with 2 m noise: the
    events in the order a live pipeline gives them ("step", Step) / ("fix", t_ns, values)."""
    rng = np.random.default_rng(seed)
    dt, length = 550_000_000, 0.7
    e = n = 0.0
    next_fix = T0 + 1_000_000_000
    side = int(60 / length)
    for k in range(n_steps):
        t = T0 + (k + 1) * dt
        while next_fix <= t:
            lat, lon = enu_to_geodetic(e + rng.normal(0, 2.0), n + rng.normal(0, 2.0), ORIGIN)
            course = (90.0 - math.degrees(heading)) % 360.0 if k else math.nan
            yield "fix", next_fix, (float(lat), float(lon), 30.0, 4.0, 1.27, course)
            next_fix += 1_000_000_000
        heading = (k // side % 4) * math.pi / 2 + rng.normal(0, 0.03)
        e += length * math.cos(heading)
        n += length * math.sin(heading)
        feats = StepFeatures(t, 0.55, 12.0, 8.0, 1.0, 1.75, window_mean_m_s2=9.9, window_freq_hz=1.8,
                             window_std_m_s2=1.5)
        yield "step", Step(k, t, length, heading, e, n, feats, True)


def _text(records) -> list:
    """Records as text (nan != nan: a read-back nan is another object, so dataclass equality fails)."""
    return [repr(r) for r in records]


def _feed(fusion, events):
    for ev in events:
        if ev[0] == "fix":
            fusion.add_fix(ev[1], ev[2])
        else:
            fusion.add_step(ev[1])


@pytest.mark.parametrize("name", ["kubrak", "chen"])
def test_a_live_fusion_holds_the_same_bytes_after_n_and_10n_steps(tmp_path, name):
    n = 250  # steps (137 s, 137 fixes); then 10 n (23 minutes)
    live = make_fusion(name, keep_history=False)
    live.history_dir = str(tmp_path)  # as the app's session sets it, after the pipeline built the fusion
    assert live.steps.directory == live.fixes.directory == str(tmp_path)
    kept = make_fusion(name)
    live.reset()
    kept.reset()
    events = list(_walk(10 * n))
    k_n = next(i for i, ev in enumerate(events) if ev[0] == "step" and ev[1].index == n - 1) + 1
    _feed(live, events[:k_n])
    _feed(kept, events[:k_n])
    assert live.origin_lat_lon is not None and live.n_fixes_accepted > 100  # anchored, fixes used
    # the same kernel: the same track and verdicts, and the file reads back every record exactly
    assert _text(live.steps) == _text(kept.steps) and _text(live.fixes) == _text(kept.fixes)
    assert live.counters()["fixes_accepted"] == kept.counters()["fixes_accepted"] > 100
    a, b = live.result(), kept.result()
    assert _text(a.steps) == _text(b.steps) and _text(a.fixes) == _text(b.fixes)
    ta, tb = FusedTrack.from_steps(live.steps), b.track()
    for col in ("t_ns", "east_m", "north_m", "sigma_m"):
        np.testing.assert_array_equal(getattr(ta, col), getattr(tb, col))
    assert ta.source == tb.source
    # what the lists hold grows with every record (before: about 560 bytes a step and 500 a fix) ...
    assert deep_bytes(kept.steps) + deep_bytes(kept.fixes) > 400 * (len(kept.steps) + len(kept.fixes))
    short = deep_bytes(live)
    _feed(live, events[k_n:])
    assert len(live.steps) == 10 * n and len(live.fixes) > 1300
    assert deep_bytes(live) <= short + 512  # ... the live fusion's does not: windows, the last 64 records, counters
    assert sum(1 for _ in live.steps) == 10 * n and live.result().counters["fixes"] == len(live.fixes)
    live.reset()  # a new track closes the old files


def test_a_record_file_reads_back_dataclasses_exactly_and_indexes_like_a_list(tmp_path):
    f = RecordFile(FixRecord, directory=str(tmp_path), keep_last=4)
    want = [FixRecord(T0 + k, 60.0 + k * 1e-7, 24.9, math.nan if k % 3 else 1.5, 2.0, 4.0, 1.2, math.inf, k % 2 == 0,
                      "" if k % 2 == 0 else f"accuracy {k} m, and a \"quote\"", 0.1 * k, 0.0) for k in range(10)]
    for r in want:
        f.append(r)
    got = list(f)
    assert len(got) == 10 and all(type(g) is FixRecord for g in got)
    assert [repr(g) for g in got] == [repr(w) for w in want]  # nan != nan: compare the text
    assert repr(f[-1]) == repr(want[-1]) and repr(f[2]) == repr(want[2])  # from memory / read back
    assert [repr(x) for x in f[3:]] == [repr(w) for w in want[3:]] and f[10:] == []
    s = RecordFile(FusedStep, directory=str(tmp_path))
    st = FusedStep(0, T0, 1.0, 2.0, math.nan, math.nan, 0.7, 0.3, (1.0, 0.1, 2.0), "dr")
    s.append(st)
    assert _text(s) == _text([st]) and isinstance(list(s)[0].cov_en_m2, tuple)
    with pytest.raises(IndexError):
        s[1]
    f.close()
    s.close()
