"""benchmarks.stride_modes (issue #25 section 4): the per-carry-mode stride scale study's fit and its support rule."""

import math

import numpy as np
import pytest

from benchmarks.stride_modes import ModeWalk, fit_scales, stats, study


def _walk(name, source, walker, mode, error_pct, n=50, other=None):
    """A walk of ``n`` steps of 0.7 m in ``mode`` (``other``: (mode, n) steps of 0.7 m more, exact) whose truth
    makes the ``mode`` steps ``error_pct`` too long."""
    lens = np.full(n, 0.7)
    modes = (mode,) * n
    truth = 0.7 * n / (1 + error_pct / 100)
    if other:
        lens = np.append(lens, np.full(other[1], 0.7))
        modes += (other[0],) * other[1]
        truth += 0.7 * other[1]
    return ModeWalk(name, source, walker, "tuning", "truth path", [(lens, modes, truth)])


def test_scale_zeroes_the_mean_error_of_two_sources():
    ws = [_walk("a", "oxiod", "x", "pocket", 10.0), _walk("b", "ridi", "y", "pocket", 20.0),
          _walk("h", "ridi", "y", "handheld", 15.0)]
    s = fit_scales(ws)
    assert set(s) == {"pocket"}  # hand-held is never scaled
    assert s["pocket"] == pytest.approx(1 / 1.15, rel=1e-9)  # 1 / mean over sources of 1 / s_walk
    assert np.mean([w.error_pct(s) for w in ws[:2]]) == pytest.approx(0.0, abs=1e-9)
    assert ws[2].error_pct(s) == pytest.approx(15.0, rel=1e-12)


def test_support_rule_one_walker_or_one_walk_is_not_enough():
    assert fit_scales([_walk("a", "ridi", "dan", "pocket", 10.0), _walk("b", "ridi", "dan", "pocket", 20.0)]) == {}
    assert fit_scales([_walk("a", "ridi", "dan", "bag", 10.0)]) == {}
    # under MIN_SHARE of its steps in the mode: not a support walk
    mixed = _walk("m", "oxiod", "x", "pocket", 10.0, n=30, other=("handheld", 20))
    assert fit_scales([mixed, _walk("b", "ridi", "y", "pocket", 20.0)]) == {}


def test_mixed_walk_scale_needed_and_leave_one_out():
    w = _walk("m", "oxiod", "x", "pocket", 10.0, n=40, other=("handheld", 10))
    s = w.scale_needed("pocket")
    assert w.error_pct({"pocket": s}) == pytest.approx(0.0, abs=1e-9)
    assert s == pytest.approx(1 / 1.1, rel=1e-9)  # the hand-held steps are exact
    ws = [_walk("a", "oxiod", "x", "pocket", 10.0), _walk("b", "ridi", "y", "pocket", 20.0),
          _walk("c", "ridi", "y", "pocket", 20.0)]
    rows = {r["walk"].name: r for r in study(ws)["rows"]}
    assert rows["a"]["lowo"] == pytest.approx(10.0, rel=1e-12)  # b and c: one walker, no scale
    assert rows["b"]["lowo"] == pytest.approx(1.2 / 1.15 * 100 - 100, rel=1e-9)  # a and c: sources alike
    assert rows["b"]["loso"] == pytest.approx(20.0, rel=1e-12)  # without ridi: one walk left, no scale


def test_failed_walk_is_counted():
    st = stats([1.0, -3.0, math.nan])
    assert st["n"] == 3 and st["median_abs"] == 3.0 and st["mean_signed"] == -1.0


def test_the_walk_cache_round_trips_as_json(tmp_path):
    # the cache was a pickle (tests/test_no_unsafe_loading.py refuses one in benchmarks/); now JSON, same walks back
    from benchmarks.stride_modes import load_walks, save_walks

    ws = [_walk("a", "oxiod", "x", "pocket", 10.0, other=("handheld", 5)), _walk("b", "ridi", "y", "bag", -3.0)]
    save_walks(tmp_path / "c.json", ws)
    back = load_walks(tmp_path / "c.json")
    assert [w.error_pct({"pocket": 0.9}) for w in back] == [w.error_pct({"pocket": 0.9}) for w in ws]
    assert [(w.name, w.source, w.walker, w.split, w.truth) for w in back] == [
        (w.name, w.source, w.walker, w.split, w.truth) for w in ws]
    assert back[0].stretches[0][1] == ws[0].stretches[0][1]


def test_a_cache_of_another_split_is_refused_not_mislabelled(tmp_path):
    # review finding: a cache of tuning walks printed under "report split"
    from benchmarks.stride_modes import main, save_walks

    save_walks(tmp_path / "c.json", [_walk("a", "oxiod", "x", "pocket", 10.0)])  # a tuning walk
    with pytest.raises(SystemExit):
        main(["--split", "report", "--cache", str(tmp_path / "c.json")])
