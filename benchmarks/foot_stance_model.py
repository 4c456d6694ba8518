"""Train the learned stance detector (issue #27): ``python -m benchmarks.foot_stance_model``.

PyShoe VICON **tuning** split only (:mod:`benchmarks.foot_splits`).  Labels by a
fixed rule: the foot's VICON speed below 0.05 m/s (:func:`benchmarks.foot.vicon_still`).
Features: :func:`core.foot.stance_model.features` (about 1 s around each sample).

1. Leave one trial out within the tuning split: for each tuning trial a model
   fitted on the other 13 labels that trial; the navigator runs on those labels
   (PyShoe's metric and our 3-D RMSE), for each candidate decision threshold
   ``p(stance) >= THRESHOLDS_P``.  The threshold with the smallest median of
   PyShoe's metric over the held-out trials is the model's.
2. The shipped model is fitted on all tuning trials (``core/foot/models/<name>.json``,
   JSON: no pickle).

The fit: L2-regularised logistic regression by Newton's method (deterministic), or with
``--hidden N`` a one-hidden-layer tanh network by full-batch gradient descent
from a seeded start.  Each trial weighs the same (sample weights 1 / its length).
Options: ``--hidden``, ``--name``, ``--no-write`` (report only), ``--seed``, ``--row-step`` (fit on every
N-th sample), ``--iters`` (gradient-descent iterations of ``--hidden``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.foot_splits import TUNING
from core.foot.navigator import gyro_at
from core.foot.stance_model import (DEFAULT_MODEL, FEATURE_NAMES, MODELS_DIR, FeatureSettings, StanceModel,
                                    features)

#: candidate decision thresholds on p(stance)
THRESHOLDS_P = (0.3, 0.5, 0.7, 0.85, 0.95)
L2 = 1e-3
SEED = 27


def tuning_data(root=None, fs: FeatureSettings | None = None) -> list[dict]:
    """Features and labels of every PyShoe tuning trial, with the recording for the navigator."""
    from benchmarks.datasets import pyshoe
    from benchmarks.foot import vicon_still

    out = []
    for tr in pyshoe.trials(root or default_data_root()):
        if tr.info["split"] != TUNING:
            continue
        rec = tr.open()
        a, g = rec.streams["acc"], rec.streams["gyro"]
        gy = gyro_at(g.t_ns, g.values, a.t_ns + int(round(tr.info["gyro_delay_s"] * 1e9)))
        x = features(a.t_ns, a.values, gy, fs)
        y = vicon_still(tr.truth_t_ns, tr.truth_pos_m).astype(float)
        out.append({"trial": tr, "rec": rec, "x": x, "y": y})
    return out


def _sigmoid(z):
    return 1.0 / (1.0 + np.exp(-np.clip(z, -50, 50)))


def fit_logistic(x, y, w, l2: float = L2) -> tuple:
    """Weighted L2 logistic regression on standardised ``x`` by Newton's method: ``(W (m, 1), b (1,))``."""
    n, m = x.shape
    X = np.column_stack([x, np.ones(n)])
    beta = np.zeros(m + 1)
    reg = np.full(m + 1, l2)
    reg[-1] = 0.0
    for _ in range(50):
        p = _sigmoid(X @ beta)
        grad = X.T @ (w * (p - y)) + reg * beta
        H = (X * (w * p * (1 - p))[:, None]).T @ X + np.diag(reg)
        step = np.linalg.solve(H + 1e-9 * np.eye(m + 1), grad)
        beta -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return (beta[:m, None], beta[m:])


def fit_mlp(x, y, w, hidden: int, seed: int = SEED, iters: int = 3000, lr: float = 0.5, l2: float = L2):
    """One tanh hidden layer, logistic output; full-batch gradient descent with momentum from a seeded start."""
    rng = np.random.default_rng(seed)
    m = x.shape[1]
    W1 = rng.normal(0, 1 / math.sqrt(m), (m, hidden))
    b1 = np.zeros(hidden)
    W2 = rng.normal(0, 1 / math.sqrt(hidden), (hidden, 1))
    b2 = np.zeros(1)
    params = [W1, b1, W2, b2]
    vel = [np.zeros_like(p) for p in params]
    ws = w / w.sum()
    for _ in range(iters):
        h = np.tanh(x @ W1 + b1)
        p = _sigmoid((h @ W2 + b2)[:, 0])
        d = (ws * (p - y))[:, None]
        gW2 = h.T @ d + l2 * W2
        gb2 = d.sum(0)
        dh = (d @ W2.T) * (1 - h * h)
        gW1 = x.T @ dh + l2 * W1
        gb1 = dh.sum(0)
        for i, g in enumerate((gW1, gb1, gW2, gb2)):
            vel[i] = 0.9 * vel[i] - lr * g
            params[i] += vel[i]
    return (W1, b1), (W2, b2)


def fit(data: list[dict], hidden: int = 0, seed: int = SEED, fs: FeatureSettings | None = None,
        threshold_p: float = 0.5, meta=None, row_step: int = 1, iters: int = 3000) -> StanceModel:
    """Fit on every ``row_step``-th sample of each trial (the features vary over tenths of a second)."""
    x = np.vstack([d["x"][::row_step] for d in data])
    y = np.concatenate([d["y"][::row_step] for d in data])
    w = np.concatenate([np.full(len(d["y"][::row_step]), 1.0 / len(d["y"][::row_step])) for d in data])
    w = w * (len(y) / w.sum())
    mean, sd = x.mean(0), x.std(0)
    sd = np.where(sd > 1e-9, sd, 1.0)
    z = (x - mean) / sd
    layers = (fit_logistic(z, y, w),) if hidden <= 0 else fit_mlp(z, y, w, hidden, seed, iters=iters)
    return StanceModel(mean, sd, tuple(layers), threshold_p, fs or FeatureSettings(), meta=meta)


def _nav_errors(d: dict, labels) -> dict:
    from benchmarks.foot import foot_settings, position_errors
    from core.foot.navigator import FootNavigator

    tr = d["trial"]
    res = FootNavigator(foot_settings("shoe", gyro_delay_s=tr.info["gyro_delay_s"])).run(d["rec"], stance=labels)
    return position_errors(res.position_n, tr.truth_pos_m)


def _f1(pred, ref) -> float:
    tp = float(np.sum(pred & ref))
    return 2 * tp / max(float(np.sum(pred)) + float(np.sum(ref)), 1.0)


def leave_one_trial_out(data, hidden: int = 0, seed: int = SEED, thresholds=THRESHOLDS_P, log=print,
                        row_step: int = 1, iters: int = 3000) -> dict:
    """Held-out p(stance) of every tuning trial and the navigator's errors at each threshold."""
    per = {th: [] for th in thresholds}
    for i, d in enumerate(data):
        m = fit([e for j, e in enumerate(data) if j != i], hidden, seed, row_step=row_step, iters=iters)
        p = m.probability(d["x"])
        for th in thresholds:
            st = p >= th
            e = _nav_errors(d, st)
            per[th].append({"trial": d["trial"].name, "rmse_3d_m": e["rmse_3d_m"], "pyshoe_2d_m": e["pyshoe_2d_m"],
                            "f1": _f1(st, d["y"] > 0.5)})
        log(f"  {d['trial'].name}: " + ", ".join(f"p>={th} {per[th][-1]['rmse_3d_m']:.3f}/"
                                                 f"{per[th][-1]['pyshoe_2d_m']:.3f}" for th in thresholds))

    def med(v):
        v = [x if math.isfinite(x) else math.inf for x in v]
        return float(np.median(v))

    summary = {str(th): {"pyshoe_metric_median_m": med([r["pyshoe_2d_m"] for r in rs]),
                         "rmse_3d_median_m": med([r["rmse_3d_m"] for r in rs]),
                         "rmse_3d_max_m": max(r["rmse_3d_m"] if math.isfinite(r["rmse_3d_m"]) else math.inf
                                              for r in rs),
                         "f1_median": med([r["f1"] for r in rs])} for th, rs in per.items()}
    return {"per_trial": {str(k): v for k, v in per.items()}, "summary": summary}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hidden", type=int, default=0, help="tanh units of one hidden layer (0: logistic regression)")
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--name", default=DEFAULT_MODEL, help="model file name in core/foot/models/")
    ap.add_argument("--no-write", action="store_true", help="report only; write no model file")
    ap.add_argument("--row-step", type=int, default=1, help="fit on every N-th sample of each trial (speed)")
    ap.add_argument("--iters", type=int, default=3000, help="--hidden: gradient-descent iterations")
    args = ap.parse_args(argv)
    t0 = time.time()
    print("features of the PyShoe tuning trials ...", file=sys.stderr)
    data = tuning_data()
    print(f"leave one trial out ({len(data)} tuning trials) ...", file=sys.stderr)
    cv = leave_one_trial_out(data, args.hidden, args.seed, log=lambda s: print(s, file=sys.stderr),
                             row_step=args.row_step, iters=args.iters)
    best = min(cv["summary"], key=lambda k: (cv["summary"][k]["pyshoe_metric_median_m"],
                                            cv["summary"][k]["rmse_3d_median_m"]))
    for k, v in cv["summary"].items():
        print(f"p(stance) >= {k}: " + ", ".join(f"{a} {b:.4f}" for a, b in v.items())
              + ("  <- chosen" if k == best else ""))
    meta = {"trained_on": "PyShoe VICON tuning split (benchmarks.foot_splits), "
                          + ", ".join(d["trial"].name for d in data),
            "labels": "VICON speed < 0.05 m/s (benchmarks.foot.vicon_still)",
            "threshold_chosen_by": "leave-one-trial-out within the tuning split, median PyShoe metric",
            "cv_summary": cv["summary"], "hidden": args.hidden, "seed": args.seed, "l2": L2,
            "row_step": args.row_step, "iters": args.iters if args.hidden > 0 else None,
            "script": "python -m benchmarks.foot_stance_model"}
    model = fit(data, args.hidden, args.seed, threshold_p=float(best), meta=meta, row_step=args.row_step,
                iters=args.iters)
    if not args.no_write:
        MODELS_DIR.mkdir(exist_ok=True)
        path = MODELS_DIR / f"{args.name}.json"
        path.write_text(json.dumps(model.to_json(), indent=1) + "\n")
        print(f"wrote {path} ({time.time() - t0:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
