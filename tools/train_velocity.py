"""Fit the velocity model of Kubrak et al. (2006), eq. 1, offline on the tuning split's walks of known speed.

``python tools/train_velocity.py [--data DIR] [--out core/pdr/models/kubrak_velocity.json]``

Samples (each a stretch of known mean speed, weighted by its duration):

* IPIN 2023 tuning routes (01, 02, 21, 22; hand-held phones): every stretch between two
  consecutive surveyed landmarks, speed = the straight distance between them over the time
  (corridor legs: the straight line is the path to within a few per cent);
* IPOL healthy gait (tuning, lower back): each 10 m straight leg over its time.

For each stretch the regressors are the duration-weighted means of the steps' eq.-1
features (:class:`core.pdr.velocity.SpeedFeatureWindow`, which the pipeline attaches to
every step).  The fit is :func:`core.pdr.velocity.fit_velocity_model`, a ridge towards a
weak prior.  Report-split walks are never read.  The result's leave-one-dataset-out error
is printed so that the coefficients are not trusted beyond what they show.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.datasets import ipin2023, ipol  # noqa: E402
from benchmarks.datasets.base import default_data_root  # noqa: E402
from benchmarks.splits import TUNING, trial_split  # noqa: E402
from core.pdr.pipeline import Pipeline  # noqa: E402
from core.pdr.velocity import DEFAULT_MODEL_PATH, VelocityModel, fit_velocity_model  # noqa: E402

#: a weak prior: a speed of 0 at rest-level features would need A ~ 0; the data decides
PRIOR = VelocityModel(0.0, 0.3, 0.1, sd=(0.05, 0.5, 0.5))
#: the shipped model's SDs are at least these (A s, B m, C s): 0.1, 0.18 and 0.1-0.3 m/s at a walker's regressors
PRIOR_SD_FLOOR = (0.01, 0.1, 0.05)


def _stretch(steps, t0: int, t1: int):
    """Duration-weighted mean regressors of the steps inside ``[t0, t1]`` (None if too few)."""
    rows, w = [], []
    for s in steps:
        f = s.features
        if t0 <= s.t_ns <= t1 and math.isfinite(f.window_mean_m_s2):
            rows.append((f.window_mean_m_s2, f.window_freq_hz, f.window_std_m_s2))
            w.append(f.duration_s)
    if len(rows) < 4:
        return None
    return np.average(np.array(rows), axis=0, weights=np.array(w))


def samples(root: Path, progress=print) -> dict:
    """{dataset: (x (n, 3), speed (n,), weight (n,))} from the tuning split."""
    out = {}
    xs, ys, ws = [], [], []
    for tr in ipin2023.trials(root):
        if trial_split(tr) != TUNING:
            continue
        rec = tr.open()
        steps = Pipeline().run(rec).steps
        lm = tr.landmarks
        for i in range(len(lm.t_ns) - 1):
            t0, t1 = int(lm.t_ns[i]), int(lm.t_ns[i + 1])
            dt = (t1 - t0) * 1e-9
            d = math.hypot(lm.east_m[i + 1] - lm.east_m[i], lm.north_m[i + 1] - lm.north_m[i])
            x = _stretch(steps, t0, t1)
            if x is not None and dt > 3.0 and d > 3.0 and 0.3 < d / dt < 2.5:
                xs.append(x), ys.append(d / dt), ws.append(dt)
        progress(f"ipin {tr.name}: {len(xs)} stretches so far")
    out["ipin2023_track3"] = (np.array(xs), np.array(ys), np.array(ws))
    xs, ys, ws = [], [], []
    for tr in ipol.trials(root):
        rec = tr.open()
        steps = Pipeline().run(rec).steps
        for t0, t1, length in tr.legs:
            dt = (t1 - t0) * 1e-9
            x = _stretch(steps, t0, t1)
            if x is not None and dt > 2.0:
                xs.append(x), ys.append(length / dt), ws.append(dt)
    progress(f"ipol: {len(xs)} legs")
    out["ipol_healthy_gait_xsens"] = (np.array(xs), np.array(ys), np.array(ws))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_root())
    ap.add_argument("--out", type=Path, default=DEFAULT_MODEL_PATH)
    args = ap.parse_args(argv)
    data = samples(args.data, progress=lambda m: print(m, file=sys.stderr))
    x = np.concatenate([d[0] for d in data.values()])
    y = np.concatenate([d[1] for d in data.values()])
    w = np.concatenate([d[2] for d in data.values()])
    model, cov = fit_velocity_model(x, y, weights=w, prior=PRIOR)
    report = {}
    for name, (xd, yd, wd) in data.items():
        others = [k for k in data if k != name]
        xo = np.concatenate([data[k][0] for k in others])
        yo = np.concatenate([data[k][1] for k in others])
        wo = np.concatenate([data[k][2] for k in others])
        mo, _ = fit_velocity_model(xo, yo, weights=wo, prior=PRIOR)
        pred = np.array([mo.speed_m_s(*r) for r in xd])
        pred_all = np.array([model.speed_m_s(*r) for r in xd])
        report[name] = {"n": int(len(yd)), "mean_speed_m_s": float(np.average(yd, weights=wd)),
                        "in_sample_err_pct": float(100 * np.median(np.abs(pred_all / yd - 1))),
                        "left_out_err_pct": float(100 * np.median(np.abs(pred / yd - 1)))}
    sd = np.sqrt(np.diag(cov))
    # the prior SDs the Kalman filter starts from: the fit's own SD is for these walkers and placements (hand,
    # lower back); a trouser pocket's STD is 4-5 times a hand's, so the floors allow about 0.3 m/s of speed
    spread = tuple(float(max(s, p)) for s, p in zip(sd, PRIOR_SD_FLOOR))
    model = VelocityModel(model.a_s, model.b_m, model.c_s, sd=spread)
    d = model.to_dict()
    d.update(name="kubrak_velocity", description="Kubrak et al. 2006 eq. 1 (v = A MEAN + B FREQ + C STD over 2 s "
             "of |a|), fitted by tools/train_velocity.py on the tuning split (IPIN 2023 routes 01/02/21/22 "
             "landmark stretches, IPOL legs)", training=report)
    args.out.write_text(json.dumps(d, indent=1) + "\n", encoding="utf-8")
    print(json.dumps(d, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
