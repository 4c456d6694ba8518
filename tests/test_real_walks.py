"""benchmarks.real_walks' measures on synthetic data with a known answer (issue #25)."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.real_walks import outage_windows, reversed_steps, stability, straight_windows


def test_stability_sd_drift_and_mean_offset():
    # course 0.5 rad; step headings off by 10 deg plus a drift of 2 deg/min and +-3 deg alternating noise
    t0 = 0
    wins, st_t, head = [], [], []
    for k in range(12):
        a = int((k * 30.0) * 1e9)
        b = a + int(29e9)
        wins.append((a, b, 0.5))
        off = math.radians(10.0 + 2.0 * (k * 30.0 + 14.5) / 60.0 + (3.0 if k % 2 else -3.0))
        for j in range(20):
            st_t.append(a + int(j * 1.4e9))
            head.append(0.5 - off)
    s = stability(wins, np.array(st_t, dtype=np.int64), np.array(head), t0)
    assert s["n_windows"] == 12
    assert abs(s["drift_deg_min"] - 2.0) < 0.3  # the +-3 deg alternation adds a little
    assert abs(s["mean_offset_deg"] - (10.0 + 2.0 * (5.5 * 30.0 + 14.5) / 60.0)) < 0.2
    assert 4.5 < s["sd_deg"] < 6.5  # sqrt(spread of the drift ramp^2 + 3^2)
    # wrapping: an offset near 180 deg has no jump in the drift
    s2 = stability(wins, np.array(st_t, dtype=np.int64), np.array(head) + math.radians(170.0), t0)
    assert abs(s2["drift_deg_min"] - s["drift_deg_min"]) < 1e-6
    assert abs(s2["mean_offset_deg"] - (s["mean_offset_deg"] - 170.0)) < 1e-6


def test_straight_windows_keep_straight_and_drop_turns():
    t = (np.arange(121) * 1e9).astype(np.int64)
    e = 1.3 * np.arange(121.0)
    n = np.zeros(121)
    n[60:] = 1.3 * np.arange(61.0)  # from 60 s on: straight north
    e[60:] = e[60]
    n[45:60] = 0.2 * (np.arange(15.0)) ** 2  # a curve inside the second window
    w = straight_windows((t, e, n, np.full(121, 4.0)), 0, int(120e9))
    courses = [round(math.degrees(c)) for _, _, c in w]
    assert 0 in courses and 90 in courses and len(w) == 3  # the curved window (30-60 s) is dropped


def test_outage_windows():
    w = outage_windows(5.0, 306.0)
    assert (65.0, 60.0) in w and (65.0, 180.0) in w and all(a + L <= 291.0 for a, L in w)
    assert not [x for x in w if x[1] == 300.0]


def test_extra_corpus_split_carry_and_grouped_summaries(tmp_path):
    """The --extra folder: repository from the folder name, split by repository (declared tuning vs report),
    the carry position from its MANIFEST.tsv, a clip from COUNTS.tsv; the grouped summaries keep failures."""
    from benchmarks.datasets.phone_walks import EXTRA, SHARED, real_walks
    from benchmarks.real_walks import corpus_meta, summarize_by

    root = tmp_path / "data"
    (root / "gps_walks_phone" / "w0").mkdir(parents=True)
    extra = tmp_path / "extra"
    for repo, walk in (("fif911__ML4QS", "a"), ("someone__walks", "b"), ("someone__walks", "c")):
        (extra / repo / walk).mkdir(parents=True)
    (extra / "MANIFEST.tsv").write_text("repository\twalk\tlocal_file\tcarry\n"
                                        "fif911/ML4QS\ta\tLocation.csv\tnot stated (inferred: flat in hand)\n"
                                        "someone/walks\tb\tLocation.csv\ttrouser pocket\n")
    (extra / "someone__walks" / "COUNTS.tsv").write_text("walk\tsteps\tpath_m\tcarry\nc\t40\t\tswinging hand\n")
    walks = real_walks(root, extra)
    by = {w.walk: w for w in walks}
    assert by["w0"].corpus == SHARED and by["w0"].split == "report"
    assert by["a"].corpus == EXTRA and by["a"].repository == "fif911/ML4QS" and by["a"].split == "tuning"
    assert by["a"].carry == "not stated (inferred: flat in hand)"
    assert by["b"].split == "report" and by["b"].carry == "trouser pocket"
    assert by["c"].kind == "step_clip" and by["c"].steps_counted == 40 and by["c"].carry == "swinging hand"
    meta = corpus_meta(root, extra, walks)
    assert meta["walks_per_corpus"] == {EXTRA: 3, SHARED: 1} and meta["extra_manifest"]["rows"] == 2
    assert meta["repositories_extra"] == ["fif911/ML4QS", "someone/walks"]
    rows = [{"name": w.name, "split": w.split, "corpus": w.corpus, "carry": w.carry, "failed": "x"} for w in walks]
    g = summarize_by(rows, "carry")
    assert g["trouser pocket"]["report"]["failed"] == ["extdata:someone__walks/b"]  # counted, not dropped
    assert set(summarize_by(rows, "corpus")) == {EXTRA, SHARED}


def test_gps_path_chords_not_noise():
    """5-s chords: a straight 1.3 m/s walk with 3-m fix noise measures near its true length, 1-s chords far more;
    a 60-s gap in the fixes is not bridged."""
    from benchmarks.real_walks import distance_in_spans, gps_path

    rng = np.random.default_rng(3)
    t = (np.arange(200) * 1e9).astype(np.int64)
    e = 1.3 * np.arange(200.0) + rng.normal(0.0, 3.0, 200)
    n = rng.normal(0.0, 3.0, 200)
    fixes = (t, e, n, np.full(200, 5.0))
    path, spans = gps_path(fixes)
    true = 1.3 * (spans[-1][1] - spans[0][0]) * 1e-9
    assert abs(path - true) < 0.12 * true
    assert gps_path(fixes, every_s=1.0)[0] > 1.5 * true  # why the chords are 5 s
    keep = (t < 80e9) | (t >= 140e9)
    gapped, gspans = gps_path((t[keep], e[keep], n[keep], np.full(keep.sum(), 5.0)))
    assert gapped < path - 0.8 * 1.3 * 60.0
    assert gps_path(None) is None
    # the PDR distance is taken over the bridged chords only: steps of 0.65 m every 0.5 s, none counted in the gap
    st_t = (np.arange(400) * 0.5e9).astype(np.int64)
    d_all = distance_in_spans(st_t, np.full(400, 0.65), spans)
    d_gap = distance_in_spans(st_t, np.full(400, 0.65), gspans)
    assert abs(d_all - 1.3 * (spans[-1][1] - spans[0][0]) * 1e-9) < 0.7
    assert abs((d_all - d_gap) - 1.3 * 65.0) < 1.0  # the 60-s gap and the chord that would bridge it


def test_periodicity_steps_counts_a_known_cadence():
    """A 60-s walk at 1.8 steps/s (magnitude with a stride component at 0.9 Hz, weaker) between 20 s of
    standing: 108 steps within 3 %, the standing not counted; a still phone gives none."""
    from benchmarks.real_walks import periodicity_steps

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 100.0, 0.01)
    walking = (t >= 20.0) & (t < 80.0)
    mag = 9.81 + walking * (2.0 * np.sin(2 * np.pi * 1.8 * t) + 0.8 * np.sin(2 * np.pi * 0.9 * t + 0.3))
    mag += rng.normal(0.0, 0.1, t.size)
    acc = np.stack([np.zeros_like(t), np.zeros_like(t), mag], axis=1)
    steps, moving = periodicity_steps(t, acc)
    assert moving == 60.0 and abs(steps - 108.0) < 0.03 * 108.0
    assert periodicity_steps(t, np.stack([np.zeros_like(t)] * 2 + [np.full_like(t, 9.81)], axis=1)) == (0.0, 0.0)


def test_reversed_steps_counts_backward_groups():
    # fixes every second walking north-east at 1.3 m/s; steps every 0.5 s, heading = course - 12 deg, except a
    # group of 8 steps turned by 180 deg (a flipped sign) and a mean offset of 12 deg that must not count
    t = (np.arange(120) * 1e9).astype(np.int64)
    course = math.radians(40.0)
    e, n = 1.3 * np.arange(120.0) * math.cos(course), 1.3 * np.arange(120.0) * math.sin(course)
    st_t = (np.arange(10, 220) * 0.5e9).astype(np.int64)
    head = np.full(len(st_t), course - math.radians(12.0))
    head[100:108] += math.pi
    head[150] = np.nan
    r = reversed_steps((t, e, n, np.full(120, 4.0)), st_t, head, 12.0)
    assert r["n"] == len(st_t) - 1
    assert abs(r["reversed_pct"] - 100.0 * 8 / r["n"]) < 1e-9
    assert reversed_steps(None, st_t, head, 12.0)["reversed_pct"] is None
    still = reversed_steps((t, np.zeros(120), np.zeros(120), np.full(120, 4.0)), st_t, head, 12.0)
    assert still["n"] == 0 and still["reversed_pct"] is None  # no chord: no course, nothing counted


def test_a_failed_walk_or_outage_counts_in_the_medians_never_dropped():
    import math

    from benchmarks.real_walks import summarize

    def gps_walk(name, sd, outages, failed=None):
        r = {"name": name, "split": "report", "kind": "gps_walk", "gps": True,
             "stability": {"sd_deg": sd, "drift_deg_min": 1.0, "mean_offset_deg": 0.0},
             "stability_device": {"sd_deg": sd}, "outages": outages}
        return dict(r, failed=failed) if failed else r

    def out(pct):
        return {"length_s": 180.0, "default_pct": pct, "pdr_pct": pct, "floor_pct": 1.0}

    rows = [gps_walk("a", 5.0, [out(10.0), out(20.0)]),
            gps_walk("b", 7.0, [out(30.0), out(None)]),  # an outage not scored: counted as inf in its walk
            gps_walk("c", None, [], failed="ValueError"),
            {"name": "d", "split": "report", "kind": "step_clip", "steps_counted": 10, "steps_error_pct": 10.0},
            {"name": "e", "split": "report", "kind": "step_clip", "steps_counted": 10, "failed": "ValueError"}]
    s = summarize(rows)["report"]
    assert s["sd_median_deg"] == 7.0  # (5, 7, inf)
    assert s["outage_180s"]["default_median_pct"] == math.inf  # walks (15, inf)
    assert s["outage_180s"]["failed_or_unmeasured"] == 1
    assert s["clip_abs_step_error_mean_pct"] == 55.0  # (10, 100: a failed clip gave no steps)
