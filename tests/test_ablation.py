"""benchmarks.ablation's numbers: a failed recording counts as the worst, never dropped; the verdict's rule."""

import math

from benchmarks import ablation as A


def _row(name, lm, loop, split="tuning", dataset="ipin2023_track3"):
    return {"dataset": dataset, "name": name, "split": split,
            "sources": {"ours": {"lm_mean_m": lm, "loop_pct": loop}}}


def test_a_failed_recording_enters_the_median_as_the_worst():
    rows = [_row("a", 1.0, 2.0), _row("b", 2.0, 3.0),
            {"dataset": "ipin2023_track3", "name": "c", "split": "tuning", "error": "ValueError: x"}]
    s = A.summarise(rows, "tuning")
    assert s["failed"] == 1 and s["n"] == 3
    assert s["ipin_lm_m"] == 2.0  # median of (1, 2, inf), not of (1, 2)
    assert s["ipin_loop_pct"] == 3.0


def test_a_walk_that_is_no_loop_is_left_out_of_the_loop_median_but_a_nan_error_is_a_failure():
    rows = [_row("a", 1.0, 2.0), _row("b", 3.0, math.nan), _row("c", math.nan, 4.0)]
    s = A.summarise(rows, "tuning")
    assert s["ipin_loop_pct"] == 3.0  # median of (2, 4)
    assert s["ipin_lm_m"] == 3.0  # median of (1, 3, inf)


def test_the_verdict_of_switching_a_mechanism_off():
    on = {"ipin_lm_m": 2.0, "ipin_loop_pct": 4.0, "ms_lm_m": 4.0, "ms_loop_pct": 10.0}
    assert A.verdict(dict(on), on) == ("inactive", 0.0)
    worse = dict(on, ipin_lm_m=2.4)  # +20 % on one of four: +5 % mean
    word, m = A.verdict(worse, on)
    assert word == "helps" and abs(m - 0.05) < 1e-12
    assert A.verdict(dict(on, ipin_lm_m=1.6), on)[0] == "hurts"
    assert A.verdict(dict(on, ipin_lm_m=2.02), on)[0] == "no effect"  # +0.25 %: within the margin
    assert A.verdict(dict(on, ms_lm_m=math.inf), on)[0] == "helps"  # failures off: worst
