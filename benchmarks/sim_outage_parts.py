"""What a simulated 5-minute outage's end error is made of, against the simulator's truth (issue #26).

``python -m benchmarks.sim_outage_parts [--split tuning|report] [--seeds N] [--lag-s S]`` runs, per seed of
:data:`benchmarks.splits.SIM_GPS_SEEDS`, :mod:`benchmarks.gnss_eval`'s simulated walk (15 minutes of city
streets, the site given, one outage of 300 s from 360 s) through the hand-held pipeline once and Chen's
filter (``ekf``, :class:`core.gnss.fusion.GpsFusion`, with ``heading_lag_s`` = ``--lag-s``) with that window
hidden, and writes ``out/benchmarks/sim_outage_parts/sim_outage_parts_<split>_lag<S>.{md,json}``.

The end error ``E`` (fused position at the last step inside the window against the phone's true position, as
``gnss_eval`` scores it) is split exactly into

* ``start``: the fused position's error at the last step before the window (``E0``); beside it the receiver's
  correlated error there (``GpsTruth.error_model_en_m``: the Gauss-Markov bias and any multipath, mean of the
  30 s before the window), which no fix can show;
* ``along``: ``sum (|dF_i| - |dT_i|) exp(j theta_i)`` over the outage's steps (``dF`` the fused step, ``dT``
  the true phone displacement over the same interval, ``theta`` its direction): the step lengths, split into
  ``scale learnt``, ``(s - s_pre) sum l_i exp(j theta_i)`` with ``s`` the stride scale the filter had at the
  window's start, ``l`` the stride model's lengths and ``s_pre`` the true scale over the minutes before
  (truth distance / model distance from 60 s to the window), and the rest (the scale's change and each step's
  own error);
* ``cross``: ``sum |dF_i| (exp(j phi_i) - exp(j theta_i))`` (``phi`` the fused step's direction): the heading,
  split (linearised, ``sum |dF_i| j x_i exp(j theta_i)`` for an angle ``x_i``; the ``lin`` column is what the
  linearisation misses) into the EKF's own smoothing (``phi - (psi + c)``, ``psi`` the step heading, ``c`` the
  heading model's correction at the window's start), ``learnt`` (``c - c*``, ``c*`` the same five-term model,
  with the same lagged regressors and ridge, fitted to the TRUE needed correction ``theta - psi`` over the
  steps of 60 s to the window: what perfect course data would have taught) and ``wander`` (``c* -
  (theta - psi)`` inside the window: what no such model learnt before the outage predicts), the wander split
  by source: the attitude filter's heading error (true minus estimated device heading), the phone's yaw to
  the walking direction (true walking minus true device heading) and the walking-direction stage (estimated
  device heading minus the step heading).

Bounds (same table): ``perfect`` is ``|E0 + wander|`` with the true stride scale: the end error a perfect
learner of the model would leave, with the model's 5-deg ridge on the harmonics and with a 20-deg one.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from benchmarks.options import out_dir
from benchmarks.splits import REPORT, SIM_GPS_SEEDS, TUNING
from core import quaternion as quat
from core.conventions import wrap_angle
from core.geodesy import geodetic_to_enu
from core.gnss.fusion import GpsFusion
from core.gnss.heading_model import LaggedRegressors

START_S, LENGTH_S, PRE_FROM_S = 360.0, 300.0, 60.0
_wrap = np.vectorize(wrap_angle)


def _circular_unwrap(a: np.ndarray) -> np.ndarray:
    m = math.atan2(float(np.mean(np.sin(a))), float(np.mean(np.cos(a))))
    return m + _wrap(a - m)


def _truth_fit(X: np.ndarray, y: np.ndarray, harmonic_sd_deg: float) -> np.ndarray:
    """The five coefficients fitted per step (each step weighing a 10-s window's 4.1 deg spread over 18 steps, the
    model's prior: 45 deg on the offset, ``harmonic_sd_deg`` on each harmonic)."""
    w = 1.0 / (math.radians(4.1) ** 2 * 18.0)
    A = w * X.T @ X + np.diag([math.radians(45.0) ** -2] + [math.radians(harmonic_sd_deg) ** -2] * 4)
    return np.linalg.solve(A, w * X.T @ y)


def one_walk(seed: int, lag_s: float = 0.0) -> dict:
    from core.pdr.pipeline import Pipeline
    from desktop.simulator import outdoor_site, outdoor_walk

    walk = outdoor_walk(seed, minutes=15.0)
    rec, truth = walk.recording, walk.truth
    pipe = Pipeline()
    pipe.set_site(*outdoor_site(rec))
    res = pipe.run(rec)
    steps, t0 = res.steps, rec.t0_ns
    a_ns, b_ns = t0 + int(START_S * 1e9), t0 + int((START_S + LENGTH_S) * 1e9)
    fu = GpsFusion(hidden_ns=[(a_ns, b_ns)], heading_lag_s=lag_s)
    fu.reset()
    fu.set_time_zero(t0)
    g = rec.streams["gps"]
    j, snap = 0, None
    for s in steps:  # GpsFusion.run's loop, with what the filter knew when the window began
        while j < len(g.t_ns) and g.t_ns[j] <= s.t_ns:
            fu.add_fix(int(g.t_ns[j]), g.values[j].tolist())
            j += 1
        if snap is None and s.t_ns >= a_ns:
            snap = {"scale": fu.stride_scale, "coef": fu.heading_model.coefficients_rad().copy(),
                    "selected": fu.heading_model.selected, "stride_samples": fu.trainer.n_stride_samples,
                    "heading_samples": fu.trainer.n_heading_samples}
        fu.add_step(s)
    while j < len(g.t_ns):
        fu.add_fix(int(g.t_ns[j]), g.values[j].tolist())
        j += 1
    fu.finish()
    fr = fu.result()
    ts = np.array([s.t_ns for s in steps], dtype=np.int64)
    fused = {s.index: s for s in fr.steps}
    ins = np.flatnonzero((ts >= a_ns) & (ts < b_ns))
    pre = np.flatnonzero((ts >= t0 + int(PRE_FROM_S * 1e9)) & (ts < a_ns))
    k0 = int(ins[0]) - 1
    span = np.arange(k0, int(ins[-1]) + 1)
    fe, fn = geodetic_to_enu(np.array([fused[steps[k].index].lat_deg for k in span]),
                             np.array([fused[steps[k].index].lon_deg for k in span]), truth.origin_lat_lon)
    F = np.asarray(fe) + 1j * np.asarray(fn)
    tp = truth.phone_position_at(ts)
    T_all = tp[:, 0] + 1j * tp[:, 1]
    T = T_all[span]
    dF, dT = np.diff(F), np.diff(T)
    lf, lt = np.abs(dF), np.abs(dT)
    phi, th = np.angle(dF), np.angle(dT)
    eth = np.exp(1j * th)
    E0, E = F[0] - T[0], F[-1] - T[-1]
    walked = float(sum(fused[steps[k].index].length_m for k in ins))
    along = np.sum((lf - lt) * eth)
    cross = np.sum(lf * (np.exp(1j * phi) - eth))
    # along: the stride scale the filter had against the truth's
    lm = np.array([steps[k].length_m for k in ins])
    lm_pre = np.array([steps[k].length_m for k in pre])
    s_pre = float(np.sum(np.abs(np.diff(T_all[pre[0] - 1: pre[-1] + 1]))) / lm_pre.sum())
    s_out = float(lt.sum() / lm.sum())
    along_learnt = (snap["scale"] - s_pre) * np.sum(lm * eth)
    # cross: the heading model's correction against the same model fitted to the truth
    lr = LaggedRegressors(lag_s)
    X = np.array([lr.update(int(t), s.heading_rad).copy() for t, s in zip(ts, steps)])
    psi = np.array([s.heading_rad for s in steps])
    at = res.attitude
    qi = np.clip(np.searchsorted(at.t_ns, ts), 0, len(at.t_ns) - 1)
    y_axis = quat.to_matrix_array(at.q_wxyz[qi])[:, :, 1]
    dev_est = np.arctan2(y_axis[:, 1], y_axis[:, 0])
    dev_true = truth.device_heading_at(ts)
    theta_all = np.angle(np.diff(T_all, prepend=T_all[0]))
    sources = {"attitude": _wrap(dev_true - dev_est), "phone yaw": _wrap(theta_all - dev_true),
               "walking direction": _wrap(dev_est - psi)}
    c = X[ins] @ snap["coef"]

    def lin(x):
        return np.sum(lf * 1j * x * eth)

    out = {"seed": seed, "lag_s": lag_s, "walked_m": walked, "end_pct": 100 * abs(E) / walked,
           "start_pct": 100 * abs(E0) / walked, "ekf_pct": 100 * abs(lin(_wrap(phi - (psi[ins] + c)))) / walked,
           "along_pct": 100 * abs(along) / walked, "along_scale_learnt_pct": 100 * abs(along_learnt) / walked,
           "along_rest_pct": 100 * abs(along - along_learnt) / walked, "cross_pct": 100 * abs(cross) / walked,
           "scale": snap["scale"], "scale_true_pre": s_pre, "scale_true_outage": s_out,
           "scale_error_pct": 100 * (snap["scale"] / s_out - 1), "selected": snap["selected"],
           "stride_samples": snap["stride_samples"], "heading_samples": snap["heading_samples"],
           "steps": len(ins), "true_steps": int(np.sum((truth.step_t_ns >= ts[k0]) & (truth.step_t_ns < ts[ins[-1]])))}
    gt = truth.gps
    near = (gt.t_ns >= a_ns - int(30e9)) & (gt.t_ns < a_ns)
    bias = gt.error_model_en_m[near].mean(axis=0)
    out["gps_bias_pct"] = 100 * math.hypot(*bias) / walked
    out["start_minus_bias_pct"] = 100 * abs(E0 - complex(*bias)) / walked
    for ridge in (5.0, 20.0):
        coef = {k: _truth_fit(X[pre], _circular_unwrap(v[pre]), ridge) for k, v in sources.items()}
        cstar = X[ins] @ sum(coef.values())
        wander = {k: _wrap(X[ins] @ coef[k] - v[ins]) for k, v in sources.items()}
        w_all = lin(sum(wander.values()))
        key = f"ridge{ridge:g}"
        out[f"cross_learnt_pct_{key}"] = 100 * abs(lin(_wrap(c - cstar))) / walked
        out[f"learnt_mean_deg_{key}"] = math.degrees(float(np.average(_wrap(c - cstar), weights=lf)))
        out[f"wander_pct_{key}"] = 100 * abs(w_all) / walked
        for k, v in wander.items():
            out[f"wander_{k}_pct_{key}"] = 100 * abs(lin(v)) / walked
        out[f"perfect_pct_{key}"] = 100 * abs(E0 + w_all) / walked
        if ridge == 5.0:
            x_all = _wrap(phi - (psi[ins] + c)) + _wrap(c - cstar) + sum(wander.values())
            out["lin_pct"] = 100 * abs(cross - lin(x_all)) / walked
    return out


COLUMNS = (("seed", "seed", "{}"), ("end_pct", "end %", "{:.2f}"), ("start_pct", "start %", "{:.2f}"),
           ("gps_bias_pct", "GPS bias at start %", "{:.2f}"), ("along_pct", "along %", "{:.2f}"),
           ("along_scale_learnt_pct", "scale learnt %", "{:.2f}"), ("scale_error_pct", "scale / true - 1 (%)", "{:+.1f}"),
           ("cross_pct", "cross %", "{:.2f}"), ("cross_learnt_pct_ridge5", "heading learnt %", "{:.2f}"),
           ("learnt_mean_deg_ridge5", "learnt - truth fit (deg)", "{:+.2f}"),
           ("wander_pct_ridge5", "wander %", "{:.2f}"), ("wander_attitude_pct_ridge5", "wander: attitude %", "{:.2f}"),
           ("wander_phone yaw_pct_ridge5", "wander: phone yaw %", "{:.2f}"),
           ("wander_walking direction_pct_ridge5", "wander: walkdir %", "{:.2f}"), ("ekf_pct", "EKF %", "{:.2f}"),
           ("lin_pct", "lin %", "{:.2f}"), ("perfect_pct_ridge5", "perfect learner %", "{:.2f}"),
           ("perfect_pct_ridge20", "perfect, ridge 20 deg %", "{:.2f}"), ("selected", "predictor", "{}"))


def markdown(rows: list[dict], split: str, lag_s: float) -> str:
    lines = [f"## Simulated 5-minute outages, end error by part ({split} seeds, `heading_lag_s` {lag_s:g})", "",
             "Written by `python -m benchmarks.sim_outage_parts` (method in its docstring). Parts in % of the "
             "distance walked in the outage (vector norms; they add as vectors, not as numbers).", "",
             "| " + " | ".join(c[1] for c in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(f.format(r[k]) for k, _, f in COLUMNS) + " |")
    med = ["median"] + [f"{np.median([abs(r[k]) if k in ('scale_error_pct', 'learnt_mean_deg_ridge5') else r[k] for r in rows]):.2f}"
                        for k, _, _ in COLUMNS[1:-1]] + [""]
    lines.append("| " + " | ".join(med) + " |")
    lines += ["", "(median row: of the absolute value for the signed columns)"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.sim_outage_parts", description=__doc__.split("\n")[0])
    ap.add_argument("--split", choices=(TUNING, REPORT), default=TUNING)
    ap.add_argument("--seeds", type=int, default=20, help="how many of the split's seeds (default 20)")
    ap.add_argument("--lag-s", type=float, default=0.0, help="GpsFusion(heading_lag_s=...) (default 0: off)")
    args = ap.parse_args(argv)
    rows = []
    for seed in SIM_GPS_SEEDS[args.split][:args.seeds]:
        rows.append(one_walk(seed, args.lag_s))
        print(f"  seed {seed}: end {rows[-1]['end_pct']:.2f} %", file=sys.stderr)
    d = out_dir("sim_outage_parts")
    stem = f"sim_outage_parts_{args.split}_lag{args.lag_s:g}"
    (d / f"{stem}.json").write_text(json.dumps(rows, indent=1, default=float))
    (d / f"{stem}.md").write_text(markdown(rows, args.split, args.lag_s))
    print(markdown(rows, args.split, args.lag_s))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
