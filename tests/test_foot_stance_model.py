"""The learned stance detector (issue #27): model file, deterministic inference, the label rule, the fit,
and the detector on the simulator's foot walk."""

import json
import math

import numpy as np

from benchmarks.foot import vicon_still
from benchmarks.foot_stance_model import fit_logistic
from core.foot.stance import StanceDetector, StanceSettings, runs
from core.foot.stance_model import (DEFAULT_MODEL, FEATURE_NAMES, FORMAT, MODELS_DIR, StanceModel, features,
                                    load_model)
from desktop.foot_simulator import footprints, simulate_foot


def _walk(rate_hz=200.0, seed=0):
    return simulate_foot(footprints([(8.4, 0.0), (4.2, math.pi / 2)]), rate_hz=rate_hz, acc_noise_m_s2=0.05,
                         gyro_noise_rad_s=0.01, seed=seed)


def _imu(w):
    return w.t_ns, w.recording.streams["acc"].values, w.recording.streams["gyro"].values


def test_shipped_model_file_is_plain_json_and_loads():
    path = MODELS_DIR / f"{DEFAULT_MODEL}.json"
    d = json.loads(path.read_text())  # plain JSON: no pickle anywhere
    assert d["format"] == FORMAT and d["features"] == list(FEATURE_NAMES)
    m = load_model()
    assert m.mean.shape == m.sd.shape == (len(FEATURE_NAMES),) and np.all(m.sd > 0)
    assert 0.0 < m.threshold_p < 1.0
    assert all(np.all(np.isfinite(W)) and np.all(np.isfinite(b)) for W, b in m.layers)
    assert m.layers[-1][0].shape[1] == 1
    assert "tuning" in m.meta["trained_on"]  # trained on the tuning split only


def test_inference_is_deterministic_and_survives_a_json_round_trip():
    t, a, g = _imu(_walk())
    m = load_model()
    x = features(t, a, g, m.feature_settings)
    p1 = m.probability(x)
    load_model.cache_clear()
    p2 = load_model().probability(features(t, a, g, m.feature_settings))
    p3 = StanceModel.from_json(json.loads(json.dumps(m.to_json()))).probability(x)
    assert np.array_equal(p1, p2)
    assert np.array_equal(p1, p3)
    assert np.all((p1 >= 0) & (p1 <= 1))


def test_label_rule_is_vicon_speed_below_5_cm_per_s():
    """Still, then 0.04 m/s (below the rule: stance), then 0.06 m/s (motion), then still again."""
    rate = 200.0
    n = 200
    speeds = np.concatenate([np.zeros(n), np.full(n, 0.04), np.full(n, 0.06), np.zeros(n)])
    x = np.concatenate([[0.0], np.cumsum(speeds[1:] / rate)])
    pos = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    t = (np.arange(len(x)) * 1e9 / rate).astype(np.int64)
    still = vicon_still(t, pos)
    inner = slice(10, -10)  # away from the changes of speed (the rule differences over 0.05 s)
    assert np.all(still[0:n][inner]) and np.all(still[n:2 * n][inner])
    assert not np.any(still[2 * n:3 * n][inner])
    assert np.all(still[3 * n:][inner])


def test_logistic_fit_recovers_known_coefficients_and_is_deterministic():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(20000, 2))
    y = (rng.random(20000) < 1 / (1 + np.exp(-(1.0 + 2.0 * x[:, 0] - x[:, 1])))).astype(float)
    w = np.ones(len(y))
    W, b = fit_logistic(x, y, w, l2=0.0)
    assert np.allclose(W[:, 0], [2.0, -1.0], atol=0.1) and abs(b[0] - 1.0) < 0.1
    W2, b2 = fit_logistic(x, y, w, l2=0.0)
    assert np.array_equal(W, W2) and np.array_equal(b, b2)


def test_learned_detector_finds_the_simulated_stances():
    """Every true stance of the simulator's walk overlaps a detected one, the detections cover most of the
    true stance (F1 >= 0.8), and no detected stance lies wholly inside a swing."""
    w = _walk()
    t, a, g = _imu(w)
    res = StanceDetector(StanceSettings(detector="learned")).detect(t, a, g)
    st, truth = res.stance, np.asarray(w.stance, dtype=bool)
    f1 = 2 * np.sum(st & truth) / (np.sum(st) + np.sum(truth))
    assert f1 >= 0.8, f1
    for s0, s1 in runs(truth):
        assert np.any(st[s0:s1 + 1]), (s0, s1)
    for s0, s1 in runs(st):
        assert np.any(truth[s0:s1 + 1]), (s0, s1)
