"""The best-per-trial statistic of benchmarks.foot_oracle_bias (issue #27): a minimum over settings per trial."""

import math

import numpy as np
import pytest

from benchmarks.foot_oracle_bias import min_of_k_median


def test_identical_settings_give_their_median_for_every_k():
    row = np.array([0.03, 0.05, 0.02, 0.04, 0.06])
    e = np.tile(row, (4, 1))
    for k in range(1, 5):
        assert min_of_k_median(e, k, draws=20) == pytest.approx(0.04, abs=1e-12)


def test_all_settings_is_the_exact_per_trial_minimum():
    e = np.array([[0.1, 0.5, 0.3], [0.2, 0.4, 0.1], [0.3, 0.6, 0.2]])
    # per-trial minima 0.1, 0.4, 0.1 -> median 0.1
    assert min_of_k_median(e, 3) == pytest.approx(0.1)


def test_equally_good_noisy_settings_look_better_the_more_are_chosen_from():
    # 10 settings with the same expected error per trial, independent noise: the best-of-k median falls with k
    # below every single setting's (the selection effect the module measures); seeded
    rng = np.random.default_rng(1)
    e = 0.04 + 0.01 * rng.standard_normal((10, 40))
    m = [min_of_k_median(e, k, draws=200, seed=2) for k in (1, 2, 5, 10)]
    assert all(a > b for a, b in zip(m, m[1:]))
    assert m[0] == pytest.approx(0.04, abs=0.004)  # one setting: about the true error
    assert m[-1] < 0.04 - 0.01  # best of 10 normal draws: about 1.5 sd lower


def test_a_failed_run_counts_as_infinite_and_bad_k_is_refused():
    e = np.array([[math.nan, 0.02, 0.03], [math.nan, 0.01, 0.05]])
    assert min_of_k_median(e, 2) == pytest.approx(0.03)  # median of (inf, 0.01, 0.03)
    with pytest.raises(ValueError):
        min_of_k_median(e, 3)
