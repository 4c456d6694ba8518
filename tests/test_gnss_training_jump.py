"""A multipath jump inside a training window teaches nothing (issue #26, the noisy-minute target).

A constant multipath offset cancels in a chord whose two ends share it, but a chord across the episode's start or
end carries it whole.  The usability judge's shape test fits a constant offset (it lets such an episode through
once the jump has left its window), so the fixes it held back and later teaches (``learn_held_back``) could hold
the jump.  The trainer now takes no stride sample from a window in which two consecutive fixes move off the window's
own pace by more than their reported accuracies allow, and ends the stretch there
(:meth:`core.gnss.training.OnlineTrainer._jump_m`).
"""

import numpy as np

from core.gnss.training import OnlineTrainer
from test_gnss_stride_weighting import _walk


def test_a_chord_across_a_multipath_jump_is_not_a_stride_sample():
    """A jump of 22 m (10 m along, 20 m across; fixes reporting 4 m) 45 s into a straight 2-minute walk: without the
    check the stretch across it gives a sample more than 20 % off (fails before the fix); with it every sample is
    within 10 % of the truth and the window with the jump says why."""
    truth = 1.05
    kw = dict(hacc_m=4.0, shift=(45, 10.0, 20.0))
    before = _walk(OnlineTrainer(jump_per_hacc=None), truth, 121, np.random.default_rng(3), **kw)
    assert max(abs(x[1] / truth - 1.0) for x in before) > 0.2
    tr = OnlineTrainer(jump_per_hacc=1.0)
    after = _walk(tr, truth, 121, np.random.default_rng(3), **kw)
    assert after and all(abs(x[1] / truth - 1.0) < 0.1 for x in after)
    assert any("jump" in w.reason for w in tr.windows)
    assert abs(tr.stride_scale / truth - 1.0) < 0.05


def test_an_ordinary_walk_loses_few_windows_to_the_check():
    """No jump: over 20 honest 2-minute walks (fixes 1 m off per axis, reporting 4 m) the check takes the stride
    sample of at most 5 % of the windows (a move 5.7 m off the pace is four SDs of the difference of two such
    fixes per axis: 3 of 240 windows with these seeds)."""
    flagged = total = 0
    for seed in range(20):
        tr = OnlineTrainer(jump_per_hacc=1.0)
        _walk(tr, 1.0, 121, np.random.default_rng(100 + seed), hacc_m=4.0)
        total += tr.n_windows
        flagged += sum("jump" in w.reason for w in tr.windows)
    assert total >= 200 and flagged <= 0.05 * total
