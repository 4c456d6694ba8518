"""benchmarks.stride_speed's within-walk slopes on synthetic steps with a known cadence exponent (issue #25)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from benchmarks.stride_speed import _stretch, pooled, slope, walk_summary
from core.pdr.stride import StepFeatures

C = 0.455


@dataclass
class _Step:
    t_ns: int
    length_m: float
    features: StepFeatures


def _walk(level: float, exponent: float, cadences, rng, noise: float = 0.0, stretch_s: float = 20.0):
    """Stretches of steps at the given cadences; the true step is Weinberg's times level * (cadence / 1.8)^exponent
    (times 1 + noise per stretch).  Returns the summary of the stretches."""
    steps, rows, t = [], [], 0.0
    for cad in cadences:
        amp = float(rng.uniform(3.0, 6.0))  # Weinberg's amplitude for this stretch
        a = t
        true = 0.0
        n = int(round(stretch_s * cad))
        for _ in range(n):
            t += 1.0 / cad
            f = StepFeatures(t_ns=int(t * 1e9), duration_s=1.0 / cad, acc_max_m_s2=9.81 + amp / 2,
                             acc_min_m_s2=9.81 - amp / 2, acc_var_m2_s4=1.0)
            w = C * amp ** 0.25
            true += w * level * (cad / 1.8) ** exponent
            steps.append(_Step(f.t_ns, w, f))
        true *= 1.0 + noise * float(rng.standard_normal())
        rows.append(_stretch(steps, int(a * 1e9), int(t * 1e9), true, C))
        t += 1.0  # a second between stretches
    return walk_summary("synthetic", "truth", rows)


def test_slope_recovers_a_known_cadence_exponent_without_noise():
    rng = np.random.default_rng(3)
    w = _walk(1.1, -0.8, [1.6, 1.7, 1.8, 1.9, 2.0], rng)
    assert w["n"] == 5
    assert abs(w["slope_cadence"] - (-0.8)) < 0.02  # the steps' count rounds the cadence a little
    assert abs(w["ratio_median"] - 1.1) < 0.01
    for r in w["stretches"]:
        assert abs(r["weinberg_step_m"] * r["cadence_hz"] - r["our_speed_m_s"]) < 0.02 * r["our_speed_m_s"]


def test_pooled_slope_removes_each_walks_level_and_its_error_is_honest():
    # two walkers, levels 0.9 and 1.3 (a between-walk difference the within-walk slope must not see), exponent 0.5,
    # 5 % noise per stretch: over 40 seeds the estimate is within 2 standard errors in about 95 % of them
    inside = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        walks = [_walk(0.9, 0.5, rng.uniform(1.5, 2.1, 8), rng, noise=0.05),
                 _walk(1.3, 0.5, rng.uniform(1.6, 2.2, 8), rng, noise=0.05)]
        b, se, n = pooled(walks)
        assert n == 16 and se > 0
        inside += abs(b - 0.5) < 2 * se
    assert 33 <= inside <= 40  # binomial(40, 0.95): 33 or more with probability > 0.99


def test_slope_degenerate_inputs_give_nan():
    assert all(math.isnan(v) for v in slope([1.0, 1.0, 1.0], [0.1, 0.2, 0.3]))
    assert all(math.isnan(v) for v in slope([1.0, 2.0], [0.1, 0.2]))
