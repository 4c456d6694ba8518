"""Stride models (issue #4): file format, inference, training, calibration, backpropagation."""

import functools
import json
import math

import numpy as np
import pytest

from core.pdr.calibration import CalibrationError, UserProfile, calibrate_known_distance
from core.pdr.stride import ConstantCoefficient, StepFeatures, WeinbergStride
from core.pdr.stride_models import (
    FORMAT_NAME, FORMAT_VERSION, MLP, ChenLinearStride, ChenNetworkStride, NetworkCoefficient, StrideModelError,
    lengths_of, load_stride_model, model_to_dict, save_stride_model, shipped_models, with_scale,
)
from desktop.stride_training import (
    TrainConfig, Walk, fit_bp, fit_chen_ann, fit_chen_linear, fit_constant, init_params, network_loss_and_grad,
)


def _features(n, rng, height=1.75):
    out = []
    for i in range(n):
        dur = rng.uniform(0.45, 0.7)
        amin = rng.uniform(7.5, 9.0)
        out.append(StepFeatures(t_ns=i * 550_000_000, duration_s=dur, acc_max_m_s2=amin + rng.uniform(2.0, 7.0),
                                acc_min_m_s2=amin, acc_var_m2_s4=rng.uniform(0.5, 4.0), height_m=height))
    return out


def _net(rng, n_in, n_hidden):
    layers = [(rng.normal(size=(n_in, n_hidden)), rng.normal(size=n_hidden)),
              (rng.normal(size=(n_hidden, 1)) * 0.3, rng.normal(size=1) * 0.1)]
    return MLP(layers, x_mean=rng.normal(size=n_in), x_std=rng.uniform(0.5, 2, size=n_in),
               x_min=np.full(n_in, -50.0), x_max=np.full(n_in, 50.0), out_mean=0.45, out_std=0.05)


def _four_models(rng):
    bp = WeinbergStride(coefficient=NetworkCoefficient(_net(rng, 2, 5), fallback_c=0.44))
    return {
        "weinberg": WeinbergStride(coefficient=0.43),
        "weinberg_bp": bp,
        "chen_linear": ChenLinearStride(a=0.1, b=0.25, c=0.02),
        "chen_ann": ChenNetworkStride(_net(rng, 4, 16)),
    }


# ---------------------------------------------------------------------------
# file format


@pytest.mark.parametrize("kind", ["weinberg", "weinberg_bp", "chen_linear", "chen_ann"])
def test_model_file_round_trip(tmp_path, kind):
    rng = np.random.default_rng(1)
    model = _four_models(rng)[kind]
    path = tmp_path / f"{kind}.json"
    save_stride_model(model, path, name=kind, placement="waist", training={"data": "synthetic"})
    d = json.loads(path.read_text())  # plain JSON, no pickle anywhere
    assert d["format"] == FORMAT_NAME and d["format_version"] == FORMAT_VERSION and d["kind"] == kind
    assert all("name" in i and "unit" in i for i in d["inputs"])
    if kind in ("weinberg_bp", "chen_ann"):
        assert len(d["normalisation"]["mean"]) == len(d["inputs"]) == len(d["normalisation"]["std"])
    back = load_stride_model(path)
    assert back.kind == kind and back.meta["placement"] == "waist"
    feats = _features(50, rng)
    np.testing.assert_array_equal([back.length_m(f) for f in feats], [model.length_m(f) for f in feats])


def test_bad_model_files_are_refused_with_the_file_named(tmp_path):
    good = model_to_dict(WeinbergStride(coefficient=0.4))
    cases = {
        "newer.json": dict(good, format_version=FORMAT_VERSION + 1),
        "kind.json": dict(good, kind="lstm"),
        "format.json": dict(good, format="something-else"),
        "unit.json": dict(model_to_dict(ChenLinearStride(a=0, b=0.3, c=0)),
                          inputs=[{"name": "step_frequency_hz", "unit": "rpm"},
                                  {"name": "acc_var_m2_s4", "unit": "(m/s^2)^2"}]),
    }
    for name, d in cases.items():
        p = tmp_path / name
        p.write_text(json.dumps(d))
        with pytest.raises(StrideModelError, match=name):
            load_stride_model(p)
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(StrideModelError, match="junk.json"):
        load_stride_model(tmp_path / "junk.json")
    with pytest.raises(StrideModelError, match="no such model"):
        load_stride_model("no_such_model_name")


def test_shipped_default_model_loads_and_gives_sane_lengths():
    assert "default" in shipped_models()
    model = load_stride_model("default")
    for name in shipped_models():
        load_stride_model(name)
    feats = _features(100, np.random.default_rng(2))
    lengths = lengths_of(model, feats)
    assert np.all((lengths > 0.3) & (lengths < 1.2))
    assert model.meta["training"]["data"]  # says which data trained it


# ---------------------------------------------------------------------------
# inference


def test_bp_inference_equals_a_hand_computation():
    w1 = np.array([[0.5, -1.0, 0.25], [2.0, 0.1, -0.3]])
    b1 = np.array([0.1, 0.0, -0.2])
    w2 = np.array([[0.3], [-0.2], [0.7]])
    b2 = np.array([0.05])
    net = MLP([(w1, b1), (w2, b2)], x_mean=[1.70, 1.8], x_std=[0.1, 0.2], x_min=[1.5, 1.0], x_max=[2.0, 2.6],
              out_mean=0.45, out_std=0.04)
    model = WeinbergStride(coefficient=NetworkCoefficient(net, fallback_c=0.44))
    f = StepFeatures(t_ns=0, duration_s=0.5, acc_max_m_s2=13.0, acc_min_m_s2=8.0, acc_var_m2_s4=2.0, height_m=1.80)
    x = [(1.80 - 1.70) / 0.1, (2.0 - 1.8) / 0.2]  # height 1.80, frequency 1/0.5 = 2 Hz
    h = [math.tanh(x[0] * w1[0, j] + x[1] * w1[1, j] + b1[j]) for j in range(3)]
    c = 0.45 + 0.04 * (sum(h[j] * w2[j, 0] for j in range(3)) + b2[0])
    assert model.coefficient.coefficient(f) == pytest.approx(c, rel=1e-12)
    assert model.length_m(f) == pytest.approx(c * (13.0 - 8.0) ** 0.25, rel=1e-12)
    # inputs are clipped to the training range: 2.3 m is treated as 2.0 m
    tall = StepFeatures(0, 0.5, 13.0, 8.0, 2.0, height_m=2.3)
    assert model.coefficient.coefficient(tall) == pytest.approx(
        model.coefficient.coefficient(StepFeatures(0, 0.5, 13.0, 8.0, 2.0, height_m=2.0)), rel=1e-12)
    # no height: the fallback constant
    assert model.coefficient.coefficient(StepFeatures(0, 0.5, 13.0, 8.0, 2.0)) == 0.44


def test_chen_models_equal_a_hand_computation():
    f = StepFeatures(t_ns=0, duration_s=0.55, acc_max_m_s2=12.5, acc_min_m_s2=8.2, acc_var_m2_s4=1.7)
    lin = ChenLinearStride(a=0.12, b=0.21, c=0.03)
    assert lin.length_m(f) == pytest.approx(0.12 + 0.21 / 0.55 + 0.03 * 1.7, rel=1e-12)
    w1 = np.arange(8, dtype=float).reshape(4, 2) / 10 - 0.3
    net = MLP([(w1, [0.1, -0.1]), ([[0.5], [-0.4]], [0.2])], x_mean=[1.8, 2, 12, 8], x_std=[0.2, 1, 2, 1],
              out_mean=0.6, out_std=0.1)
    x = np.array([(1 / 0.55 - 1.8) / 0.2, (1.7 - 2) / 1, (12.5 - 12) / 2, (8.2 - 8) / 1])
    h = np.tanh(x @ w1 + [0.1, -0.1])
    expect = 0.6 + 0.1 * (0.5 * h[0] - 0.4 * h[1] + 0.2)
    assert ChenNetworkStride(net).length_m(f) == pytest.approx(expect, rel=1e-12)


def test_batch_lengths_equal_per_step_lengths_for_every_model():
    rng = np.random.default_rng(3)
    feats = _features(40, rng) + _features(5, rng, height=None)
    for model in list(_four_models(rng).values()) + [with_scale(WeinbergStride(), 1.1)]:
        np.testing.assert_allclose(lengths_of(model, feats), [model.length_m(f) for f in feats], rtol=1e-12)


def test_single_step_inference_keeps_no_state_between_steps():
    """The phone calls ``length_m`` once per step: a step's length must not depend on the steps before it.

    (This test used to assert a per-step wall-clock limit; speed targets live in the benchmarks.)
    """
    rng = np.random.default_rng(4)
    models = _four_models(rng)
    f = _features(1, rng)[0]
    others = _features(50, rng) + _features(5, rng, height=None)
    for name, model in models.items():
        first = model.length_m(f)
        assert math.isfinite(first) and 0.2 < first < 1.5, f"{name}: {first} m is not a step length"
        again = []
        for g in others:
            model.length_m(g)
            again.append(model.length_m(f))
        np.testing.assert_allclose(again, first, rtol=1e-12, atol=0,
                                   err_msg=f"{name}: the length of one step changed with the steps before it")
        np.testing.assert_allclose(lengths_of(model, [f]), [first], rtol=1e-12, atol=0,
                                   err_msg=f"{name}: batch and single-step lengths differ")


# ---------------------------------------------------------------------------
# training


def test_backpropagation_gradient_matches_finite_differences():
    rng = np.random.default_rng(5)
    n_steps, n_walks = 60, 6
    xn = rng.normal(size=(n_steps, 2))
    mult = rng.uniform(1.2, 1.6, size=n_steps)
    idx = np.repeat(np.arange(n_walks), n_steps // n_walks)
    dist = rng.uniform(5, 8, size=n_walks)
    params = init_params(2, 5, rng)
    params[2] = rng.normal(size=params[2].shape)  # not near zero, so every gradient is exercised
    params[1] = rng.normal(size=params[1].shape)
    args = (xn, mult, idx, dist, 0.45, 0.05, 1e-3)
    _, grads = network_loss_and_grad(params, *args)
    eps = 1e-6
    for k, p in enumerate(params):
        for i in np.ndindex(p.shape):
            plus = [q.copy() for q in params]
            minus = [q.copy() for q in params]
            plus[k][i] += eps
            minus[k][i] -= eps
            numeric = (network_loss_and_grad(plus, *args)[0] - network_loss_and_grad(minus, *args)[0]) / (2 * eps)
            assert grads[k][i] == pytest.approx(numeric, rel=1e-5, abs=1e-9), (k, i)


def _synthetic_walkers(c_of, n_walkers=8, walks_each=4, steps=40, seed=6, length_fn=None):
    """Walks whose distance is exactly sum C(h, f) * amp^(1/4) (or sum length_fn(f))."""
    rng = np.random.default_rng(seed)
    walks = []
    for w in range(n_walkers):
        h = 1.55 + 0.4 * w / (n_walkers - 1)
        base_f = rng.uniform(1.5, 2.1)
        for k in range(walks_each):
            feats = []
            for i in range(steps):
                f = base_f + rng.normal(0, 0.08)
                amin = rng.uniform(7.5, 9.0)
                amp = rng.uniform(2.5, 7.0)
                feats.append(StepFeatures(i * 550_000_000, 1 / f, amin + amp, amin, rng.uniform(0.5, 4.0), h))
            if length_fn is None:
                d = sum(c_of(x.height_m, x.frequency_hz) * (x.acc_max_m_s2 - x.acc_min_m_s2) ** 0.25 for x in feats)
            else:
                d = sum(length_fn(x) for x in feats)
            walks.append(Walk(f"w{w}-{k}", f"walker{w}", feats, float(d)))
    return walks


def test_constant_and_linear_fits_recover_their_parameters_exactly():
    walks = _synthetic_walkers(lambda h, f: 0.47)
    assert fit_constant(walks).coefficient.c == pytest.approx(0.47, rel=1e-9)
    lin = _synthetic_walkers(None, length_fn=lambda x: 0.1 + 0.2 * x.frequency_hz + 0.03 * x.acc_var_m2_s4)
    m = fit_chen_linear(lin, ridge=0.0)
    assert (m.a, m.b, m.c) == pytest.approx((0.1, 0.2, 0.03), rel=1e-6)


def test_bp_training_recovers_a_known_mapping_on_unseen_walkers():
    def c_of(h, f):
        return 0.30 + 0.25 * (h - 1.55) + 0.06 * (f - 1.5)

    walks = _synthetic_walkers(c_of, n_walkers=10)
    test = [w for w in walks if w.group in ("walker3", "walker6")]
    train = [w for w in walks if w not in test]
    cfg = TrainConfig(bp_weight_decay=0.0, max_epochs=3000)
    model = fit_bp(train, cfg)
    const = fit_constant(train)
    err = [abs(lengths_of(model, w.features).sum() / w.distance_m - 1) for w in test]
    err_const = [abs(lengths_of(const, w.features).sum() / w.distance_m - 1) for w in test]
    assert max(err) < 0.01, err
    assert np.mean(err) < 0.3 * np.mean(err_const)
    # the network's C follows the mapping
    f = StepFeatures(0, 1 / 1.8, 13, 8, 2, height_m=1.70)
    assert model.coefficient.coefficient(f) == pytest.approx(c_of(1.70, 1.8), rel=0.02)


def test_chen_network_learns_a_known_mapping():
    def length(x):
        return 0.25 + 0.18 * x.frequency_hz + 0.05 * math.tanh(x.acc_var_m2_s4 - 2)

    walks = _synthetic_walkers(None, length_fn=length, n_walkers=8, seed=7)
    model = fit_chen_ann(walks[4:], TrainConfig(chen_weight_decay=0.0, max_epochs=2000))
    err = [abs(lengths_of(model, w.features).sum() / w.distance_m - 1) for w in walks[:4]]
    assert max(err) < 0.02, err


def test_training_is_reproducible():
    walks = _synthetic_walkers(lambda h, f: 0.3 + 0.2 * (h - 1.5), n_walkers=5, walks_each=2, steps=20)
    cfg = TrainConfig(max_epochs=200)
    a = model_to_dict(fit_bp(walks, cfg))
    b = model_to_dict(fit_bp(walks, cfg))
    assert a == b


# ---------------------------------------------------------------------------
# calibration


def _sim_steps(length_m, step_length_m=0.70, seed=21):
    """The steps of a simulated straight walk (a new list of the same frozen steps: each walk run once per process,
    the 20 m one is walked by seven tests)."""
    return list(_sim_steps_once(length_m, step_length_m, seed))


@functools.cache
def _sim_steps_once(length_m, step_length_m, seed):
    from core.pdr.pipeline import Pipeline
    from desktop.simulator import simulate_walk

    walk = simulate_walk([(0, 0), (0, length_m)], step_length_m=step_length_m, seed=seed)
    return tuple(Pipeline(height_m=1.75).run(walk.recording).steps)


def test_calibration_on_a_synthetic_walk_reaches_the_known_length(tmp_path):
    base = WeinbergStride(coefficient=0.40)  # deliberately wrong C: the simulated walker's C is 0.47
    steps = _sim_steps(20.0)
    res = calibrate_known_distance(steps, 20.0, base, profile=UserProfile(height_m=1.75))
    assert res.model_distance_m < 19.0  # the wrong C was wrong
    model = res.profile.stride_model(base)
    assert sum(model.length_m(s.features) for s in steps) == pytest.approx(20.0, rel=1e-9)
    # the same walker on another, longer walk
    other = _sim_steps(60.0, seed=22)
    d = sum(model.length_m(s.features) for s in other)
    assert d == pytest.approx(60.0, rel=0.03)
    # persisted and read back
    path = tmp_path / "profile.json"
    res.profile.save(path)
    back = UserProfile.load(path)
    assert back == res.profile and back.calibrated and back.c_scale == pytest.approx(res.scale)


def test_calibrations_pool_and_ignore_other_model_versions():
    base = WeinbergStride(coefficient=0.45)
    steps = _sim_steps(20.0)
    r1 = calibrate_known_distance(steps, 20.0, base)
    r2 = calibrate_known_distance(steps, 21.0, base, profile=r1.profile)
    expect = (20.0 + 21.0) / (2 * r1.model_distance_m)
    assert r2.scale == pytest.approx(expect, rel=1e-12)
    other = WeinbergStride(coefficient=ConstantCoefficient(c=0.45))
    other.model_id = "another-model@2099"
    r3 = calibrate_known_distance(steps, 20.0, other, profile=r2.profile)
    assert r3.scale == pytest.approx(r3.walk_scale) and any("another model" in w for w in r3.warnings)


@pytest.mark.parametrize("distance, match", [
    (-20.0, "positive"), (float("nan"), "positive"), ("twenty", "number"), (3.0, "too short"),
    (2000.0, "per step"),  # centimetres typed as metres
    (6.0, "per step"),  # far too many steps for 6 m
])
def test_calibration_refuses_silly_inputs(distance, match):
    steps = _sim_steps(20.0)
    with pytest.raises(CalibrationError, match=match):
        calibrate_known_distance(steps, distance, WeinbergStride())


def test_calibration_refuses_too_few_steps_and_absurd_factors():
    steps = _sim_steps(20.0)
    with pytest.raises(CalibrationError, match="only 3 steps"):
        calibrate_known_distance(steps[:3], 20.0, WeinbergStride())
    with pytest.raises(CalibrationError, match="factor"):
        calibrate_known_distance(steps, 20.0, WeinbergStride(coefficient=0.15, min_length_m=0.05))
    with pytest.raises(CalibrationError, match="StepFeatures"):
        calibrate_known_distance([1, 2, 3], 20.0, WeinbergStride())
    with pytest.raises(CalibrationError, match="height"):
        UserProfile(height_m=175)  # centimetres


def test_scaled_models_scale_every_kind():
    rng = np.random.default_rng(8)
    feats = _features(30, rng)
    for model in _four_models(rng).values():
        scaled = with_scale(model, 1.08)
        np.testing.assert_allclose(lengths_of(scaled, feats), 1.08 * lengths_of(model, feats), rtol=1e-12)


def test_constant_coefficient_default_is_the_shipped_model():
    """core.pdr.stride's default C and core/pdr/models/default.json must not drift apart."""
    from core.pdr.stride import ConstantCoefficient
    from core.pdr.stride_models import load_stride_model

    shipped = load_stride_model("default")
    assert shipped.coefficient.c == pytest.approx(ConstantCoefficient().c, abs=5e-4)


def test_phone_distance_chords_and_walk_c():
    """benchmarks.stride_eval's phone-distance study (issue #25): a straight walk's GPS chord is its distance,
    a fix with a poor reported accuracy keeps its window out, and a walk's own C is the ratio of sums (surveyed
    truth) or the median over the stretches (GPS chords: one spoilt stretch does not move it)."""
    from types import SimpleNamespace

    from benchmarks.stride_eval import PhoneWalk, chord_stretches, fit_phone_c
    from core.geodesy import enu_to_geodetic

    t_s = np.arange(0.0, 200.0, 1.0)  # fixes at 1 Hz, walking north at 1.4 m/s
    lat, lon = enu_to_geodetic(np.zeros_like(t_s), 1.4 * t_s, (47.0, 8.0))
    hacc = np.full_like(t_s, 4.0)
    hacc[120:125] = 30.0  # a poor stretch
    vals = np.column_stack([lat, lon, np.zeros_like(t_s), hacc, np.full_like(t_s, 1.4), np.zeros_like(t_s)])
    gps = SimpleNamespace(values=vals, t_ns=(t_s * 1e9).astype(np.int64), rate_hz=1.0)
    step_t = np.arange(0.25, 200.0, 0.5)
    steps = [SimpleNamespace(t_ns=int(t * 1e9), features=StepFeatures(int(t * 1e9), 0.5, 11.0, 9.0, 0.5))
             for t in step_t]
    out = chord_stretches(steps, gps)
    assert len(out) >= 2
    for feats, chord in out:
        assert chord == pytest.approx(1.4 * 40.0, rel=0.03)
        assert len(feats) == pytest.approx(80, abs=2)
        t = np.array([f.t_ns for f in feats]) * 1e-9
        assert not np.any((t > 118.0) & (t < 127.0))  # no stretch through the poor fixes
    root = 2.0 ** 0.25  # every step's (A_max - A_min) ** (1/4)
    good = [([StepFeatures(0, 0.5, 11.0, 9.0, 0.5)] * 10, 10 * 0.48 * root)] * 3
    chords = PhoneWalk("w", "d", "tuning", "gps_chords", good + [(good[0][0], 100.0)])  # one GPS jump
    assert chords.c_needed() == pytest.approx(0.48)
    surveyed = PhoneWalk("s", "d", "tuning", "landmarks", [(good[0][0], 10 * 0.5 * root)])
    assert surveyed.c_needed() == pytest.approx(0.5)
    assert surveyed.error_pct(0.55) == pytest.approx(10.0)
    report = PhoneWalk("r", "d", "report", "landmarks", [(good[0][0], 10 * 0.9 * root)])
    c = fit_phone_c([surveyed, report])  # the report walk is never used
    assert c == pytest.approx(0.5)


def _walk(name, dataset, split, c_walk, truth="landmarks", mode="handheld", n=10):
    """A phone walk whose own C is ``c_walk``: ``n`` steps of (A_max - A_min) = 2 m/s^2, all in ``mode``."""
    from benchmarks.stride_eval import PhoneWalk

    feats = [StepFeatures(0, 0.5, 11.0, 9.0, 0.5)] * n
    return PhoneWalk(name, dataset, split, truth, [(feats, n * c_walk * 2.0 ** 0.25)], modes=[[mode] * n])


def test_phone_fit_weighs_sources_alike_and_leaves_one_out():
    """issue #25: the phone C gives zero mean signed error with every dataset weighted alike (16 walks of one
    source do not outvote one of another), a carry mode's own C comes from its walks only, leave-one-dataset-out
    scores each dataset with the fit on the others, and the report split is never used."""
    from benchmarks.stride_eval import CarryC, error_stats, fit_carry_c, fit_phone_c, leave_one_dataset_out

    walks = [_walk(f"a{k}", "A", "tuning", 0.45) for k in range(16)] + [_walk("b", "B", "tuning", 0.55, mode="bag")]
    walks.append(_walk("r", "R", "report", 0.90))
    c = fit_phone_c(walks)
    assert c == pytest.approx(1.0 / (0.5 / 0.45 + 0.5 / 0.55))  # harmonic mean of the two sources
    ca, cb = (walks[0].error_pct(c), walks[16].error_pct(c))
    assert (ca + cb) / 2 == pytest.approx(0.0, abs=1e-9)  # zero mean signed error over the sources
    carry = fit_carry_c(walks)
    assert dict(carry.by_mode) == pytest.approx({"handheld": 0.45, "bag": 0.55})
    assert walks[16].error_pct(carry) == pytest.approx(0.0, abs=1e-9)
    assert walks[16].error_pct(CarryC(0.45, (("bag", 0.66),))) == pytest.approx(20.0)
    rows = {ds: (m, errs) for ds, m, errs in leave_one_dataset_out(walks)}
    assert set(rows) == {"A", "B"}
    assert rows["B"][0] == pytest.approx(0.45) and rows["B"][1][0][1] == pytest.approx(100 * (0.45 / 0.55 - 1))
    st = error_stats([1.0, -3.0, float("nan")])  # a failed walk counts, at +inf in the median
    assert st == {"n": 3, "failed": 1, "median_abs_pct": 3.0, "mean_signed_pct": -1.0}



def test_phone_default_file_states_its_fit_and_round_trips(tmp_path):
    """``tools.train_stride --phones`` writes a default whose C gives its tuning walks the tuning error it states
    (recomputed from the walks' own C it lists), names no report walk, and loads back as that Weinberg C."""
    from benchmarks.stride_eval import write_phone_default
    from core.pdr.stride_models import MODELS_DIR, load_stride_model

    walks = [_walk(f"a{k}", "A", "tuning", 0.44 + 0.01 * k) for k in range(5)]
    walks += [_walk("b", "B", "tuning", 0.50, truth="gps_chords", mode="bag"), _walk("r", "R", "report", 0.7)]
    old = json.loads((MODELS_DIR / "default.json").read_text(encoding="utf-8"))
    d = write_phone_default(walks, old, tmp_path / "default.json", created="2026-12-06T00:00:00+00:00")
    phones = d["training"]["phones"]
    assert [w["name"] for w in phones["walks"]] == ["a0", "a1", "a2", "a3", "a4", "b"]  # the report walk never
    errs = np.array([100 * (d["c"] / w["c"] - 1) for w in phones["walks"]])
    assert np.median(np.abs(errs)) == pytest.approx(phones["tuning_error_pct"]["median_abs"], abs=0.05)
    assert phones["c_before"] == old["c"] and d["training"]["data"] == old["training"]["data"]  # IPOL's kept
    assert {r["held_out"] for r in phones["leave_one_dataset_out"]} == {"A", "B"}
    model = load_stride_model(tmp_path / "default.json")
    assert model.coefficient.c == pytest.approx(d["c"], rel=1e-12)
    f = StepFeatures(0, 0.5, 12.0, 8.0, 0.5)
    assert model.length_m(f) == pytest.approx(d["c"] * 4.0 ** 0.25)
