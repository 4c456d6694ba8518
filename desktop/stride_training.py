"""Training of the step-length models of ``core.pdr.stride_models`` (desktop only; nothing in ``core/`` imports it).

The command line is ``tools/train_stride.py``; the benchmark's stride section
(:mod:`benchmarks.stride_eval`) uses the same fitting code from here.

Training data are *walks*: stretches of detected steps (features from
``core.pdr.pipeline``) whose walked distance is known, grouped by walker.  Every
model is fitted by the same objective, the squared relative distance error of
each walk::

    J = sum_w ( (sum_{i in w} L_i - D_w) / D_w )^2 / n_walks  +  lambda * |weights|^2

so a walk of 20 m with annotated steps, a landmark-to-landmark segment or a
trundle-wheel walk all count the same way, and the per-step length ``L_i`` of
every model is trained to add up to the distance the walker really covered
with the steps the detector really found.

* ``weinberg``: closed form (``C = sum S_w/D_w / sum S_w^2/D_w^2`` with
  ``S_w = sum (A_max - A_min)^(1/4)``).
* ``chen_linear``: linear least squares on the per-walk sums (small ridge).
* ``weinberg_bp`` (Tian et al.): C = network(height, step frequency);
  ``chen_ann`` (Chen et al.): length = network(SF, SV, A_max, A_min), 16 tanh
  hidden units.  Backpropagation written out below (:func:`network_loss_and_grad`,
  checked against finite differences in the tests), full-batch Adam, input
  normalisation, L2 weight decay, early stopping on held-out *walkers*, a fixed
  seed (same inputs -> bit-identical weights).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from core.pdr.stride import StepFeatures, WeinbergStride
from core.pdr.stride_models import (
    MLP, ChenLinearStride, ChenNetworkStride, NetworkCoefficient, feature_matrix, weinberg_root,
)

MODEL_KINDS = ("weinberg", "weinberg_bp", "chen_linear", "chen_ann")
BP_INPUTS = ("height_m", "step_frequency_hz")


@dataclass
class Walk:
    """A stretch of detected steps whose walked distance is known."""

    name: str
    group: str  #: the walker (cross-validation leaves groups out)
    features: list[StepFeatures]
    distance_m: float
    dataset: str = ""
    placement: str = ""
    #: reference step count (annotated), if known
    ref_steps: int | None = None
    meta: dict = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(self.features)


@dataclass
class TrainConfig:
    """Hyper-parameters (the defaults are what trained the shipped models)."""

    seed: int = 20140510
    bp_hidden: int = 6  #: hidden tanh units of the BP coefficient network (the paper does not say)
    chen_hidden: int = 16  #: Chen et al.: "a 16-node hidden layer with the 'tansig' transfer function"
    bp_weight_decay: float = 1e-3  #: L2 on the BP network's weights (strong: the data hold only ~9 distinct heights)
    chen_weight_decay: float = 1e-4  #: L2 on Chen's network's weights
    learning_rate: float = 0.01
    max_epochs: int = 4000
    patience: int = 300  #: early stopping: epochs without a better validation loss
    val_fraction: float = 0.25  #: share of the training walkers held out for early stopping
    restarts: int = 3  #: random initialisations; the best validation loss wins
    ridge: float = 1e-6  #: chen_linear


# ---------------------------------------------------------------------------
# the walk objective


def _walk_index(walks: Sequence[Walk]) -> tuple[list[StepFeatures], np.ndarray, np.ndarray]:
    feats, idx = [], []
    for k, w in enumerate(walks):
        feats.extend(w.features)
        idx.extend([k] * w.n_steps)
    return feats, np.asarray(idx, np.int64), np.array([w.distance_m for w in walks], float)


def walk_sums(per_step: np.ndarray, walk_idx: np.ndarray, n_walks: int) -> np.ndarray:
    return np.bincount(walk_idx, weights=per_step, minlength=n_walks)


# ---------------------------------------------------------------------------
# closed-form models


def fit_constant(walks: Sequence[Walk]) -> WeinbergStride:
    """Weinberg with one C minimising the relative distance error of the walks."""
    feats, idx, dist = _walk_index(walks)
    s = walk_sums(weinberg_root(feats), idx, len(walks))
    ok = s > 0
    if not ok.any():
        raise ValueError("no steps with an acceleration amplitude to fit C on")
    c = float(np.sum(s[ok] / dist[ok]) / np.sum((s[ok] / dist[ok]) ** 2))
    return WeinbergStride(coefficient=c)


def fit_chen_linear(walks: Sequence[Walk], ridge: float = 1e-6) -> ChenLinearStride:
    """Chen's ``a + b*SF + c*SV`` by least squares on the relative walk errors."""
    feats, idx, dist = _walk_index(walks)
    x = feature_matrix(feats, ("step_frequency_hz", "acc_var_m2_s4"))
    n = len(walks)
    a_col = walk_sums(np.ones(len(feats)), idx, n)
    b_col = walk_sums(x[:, 0], idx, n)
    c_col = walk_sums(x[:, 1], idx, n)
    m = np.stack([a_col, b_col, c_col], axis=1) / dist[:, None]
    scale = np.maximum(np.abs(m).max(axis=0), 1e-12)  # column scaling for conditioning
    ms = m / scale
    coef = np.linalg.solve(ms.T @ ms + ridge * np.eye(3), ms.T @ np.ones(n)) / scale
    return ChenLinearStride(a=coef[0], b=coef[1], c=coef[2])


# ---------------------------------------------------------------------------
# networks: parameters, forward, backpropagation


def init_params(n_in: int, n_hidden: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Xavier-uniform hidden layer; a small output layer (the network starts near its output mean)."""
    lim = math.sqrt(6.0 / (n_in + n_hidden))
    w1 = rng.uniform(-lim, lim, size=(n_in, n_hidden))
    b1 = np.zeros(n_hidden)
    w2 = rng.uniform(-0.1, 0.1, size=(n_hidden, 1))
    b2 = np.zeros(1)
    return [w1, b1, w2, b2]


def network_forward(params, xn):
    w1, b1, w2, b2 = params
    h = np.tanh(xn @ w1 + b1)
    return (h @ w2 + b2)[:, 0], h


def network_loss_and_grad(params, xn, mult, walk_idx, dist, out_mean, out_std, weight_decay):
    """Walk objective of a one-hidden-layer tanh network and its gradient (backpropagation).

    Per step: ``y = out_mean + out_std * net(xn)``, ``L = y * mult`` (mult is
    ``(A_max - A_min)^(1/4)`` when the network gives Weinberg's C, 1 when it
    gives the length).  ``J = mean_w ((sum_w L - D_w) / D_w)^2 + wd * (|W1|^2 + |W2|^2)``.

    Returns ``(J, [dJ/dW1, dJ/db1, dJ/dW2, dJ/db2])``.
    """
    w1, b1, w2, b2 = params
    n_walks = len(dist)
    z, h = network_forward(params, xn)
    length = (out_mean + out_std * z) * mult
    s = walk_sums(length, walk_idx, n_walks)
    r = (s - dist) / dist
    loss = float(np.mean(r * r)) + weight_decay * float(np.sum(w1 * w1) + np.sum(w2 * w2))
    # backward
    ds = 2.0 * r / dist / n_walks  # dJ/dS_w
    dz = ds[walk_idx] * mult * out_std  # dJ/dz_i
    dw2 = h.T @ dz[:, None] + 2.0 * weight_decay * w2
    db2 = np.array([dz.sum()])
    dh = dz[:, None] * w2[:, 0][None, :]
    da = dh * (1.0 - h * h)  # tanh'
    dw1 = xn.T @ da + 2.0 * weight_decay * w1
    db1 = da.sum(axis=0)
    return loss, [dw1, db1, dw2, db2]


def _adam_train(params, train, val, cfg: TrainConfig, weight_decay: float):
    """Full-batch Adam with early stopping on ``val``; returns (best params, best val loss, epochs)."""
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    b1c, b2c, eps = 0.9, 0.999, 1e-8
    best = (math.inf, [p.copy() for p in params], 0)
    since_best = 0
    for epoch in range(1, cfg.max_epochs + 1):
        _, grads = network_loss_and_grad(params, *train, weight_decay)
        for k, g in enumerate(grads):
            m[k] = b1c * m[k] + (1 - b1c) * g
            v[k] = b2c * v[k] + (1 - b2c) * g * g
            mh = m[k] / (1 - b1c ** epoch)
            vh = v[k] / (1 - b2c ** epoch)
            params[k] = params[k] - cfg.learning_rate * mh / (np.sqrt(vh) + eps)
        vloss, _ = network_loss_and_grad(params, *val, 0.0) if val is not None else \
            network_loss_and_grad(params, *train, 0.0)
        if vloss < best[0] - 1e-12:
            best = (vloss, [p.copy() for p in params], epoch)
            since_best = 0
        else:
            since_best += 1
            if since_best >= cfg.patience:
                break
    return best[1], best[0], best[2]


def _split_validation(walks: Sequence[Walk], cfg: TrainConfig, rng: np.random.Generator):
    """Training and early-stopping walks: whole walkers held out (walks at random if only one walker)."""
    groups = sorted({w.group for w in walks})
    if len(groups) >= 3:
        n_val = max(1, int(round(cfg.val_fraction * len(groups))))
        val_groups = set(rng.choice(groups, size=n_val, replace=False).tolist())
        tr = [w for w in walks if w.group not in val_groups]
        va = [w for w in walks if w.group in val_groups]
    else:
        order = rng.permutation(len(walks))
        n_val = max(1, int(round(cfg.val_fraction * len(walks)))) if len(walks) >= 4 else 0
        va = [walks[i] for i in order[:n_val]]
        tr = [walks[i] for i in order[n_val:]]
    return tr, va


def _pack(walks, names, mult_fn):
    feats, idx, dist = _walk_index(walks)
    return feature_matrix(feats, names), mult_fn(feats), idx, dist


def fit_network(walks: Sequence[Walk], *, input_names: Sequence[str], n_hidden: int, weinberg: bool,
                cfg: TrainConfig, weight_decay: float, seed_offset: int = 0) -> tuple[MLP, dict]:
    """Train a one-hidden-layer network on the walk objective; returns the network and a training report."""
    rng = np.random.default_rng(cfg.seed + seed_offset)
    walks = [w for w in walks if w.n_steps > 0]
    if weinberg and "height_m" in input_names:
        walks = [w for w in walks if all(f.height_m is not None for f in w.features)]
    if len(walks) < 2:
        raise ValueError("need at least two walks with the inputs present to train a network")
    tr, va = _split_validation(walks, cfg, rng)
    mult_fn = weinberg_root if weinberg else (lambda feats: np.ones(len(feats)))
    x_tr, mult_tr, idx_tr, d_tr = _pack(tr, input_names, mult_fn)
    x_mean = x_tr.mean(axis=0)
    x_std = x_tr.std(axis=0)
    x_std = np.where(x_std > 1e-9, x_std, 1.0)
    # output scaling: the per-walk quantity the network predicts
    per_walk = d_tr / np.maximum(walk_sums(mult_tr, idx_tr, len(tr)), 1e-9)
    out_mean = float(np.sum(d_tr) / np.sum(walk_sums(mult_tr, idx_tr, len(tr))))
    out_std = float(max(np.std(per_walk), 0.02 * out_mean))
    train = ((x_tr - x_mean) / x_std, mult_tr, idx_tr, d_tr, out_mean, out_std)
    val = None
    if va:
        x_va, mult_va, idx_va, d_va = _pack(va, input_names, mult_fn)
        val = ((x_va - x_mean) / x_std, mult_va, idx_va, d_va, out_mean, out_std)
    best = None
    for k in range(max(1, cfg.restarts)):
        params = init_params(len(input_names), n_hidden, rng)
        p, vloss, epochs = _adam_train(params, train, val, cfg, weight_decay)
        if best is None or vloss < best[1]:
            best = (p, vloss, epochs, k)
    p, vloss, epochs, k = best
    all_x = np.concatenate([x_tr] + ([_pack(va, input_names, mult_fn)[0]] if va else []))
    net = MLP([(p[0], p[1]), (p[2], p[3])], x_mean=x_mean, x_std=x_std,
              x_min=all_x.min(axis=0), x_max=all_x.max(axis=0), out_mean=out_mean, out_std=out_std)
    report = {"train_walks": len(tr), "val_walks": len(va), "val_groups": sorted({w.group for w in va}),
              "val_rms_rel_error": math.sqrt(vloss), "epochs": epochs, "restart": k}
    return net, report


def fit_bp(walks: Sequence[Walk], cfg: TrainConfig | None = None) -> WeinbergStride:
    """The paper's BP network: C = net(height, step frequency), inside Weinberg's eq. 4."""
    cfg = cfg or TrainConfig()
    const = fit_constant(walks).coefficient.c
    net, report = fit_network(walks, input_names=BP_INPUTS, n_hidden=cfg.bp_hidden, weinberg=True, cfg=cfg,
                              weight_decay=cfg.bp_weight_decay)
    model = WeinbergStride(coefficient=NetworkCoefficient(net, input_names=BP_INPUTS, fallback_c=const))
    model.train_report = report
    return model


def fit_chen_ann(walks: Sequence[Walk], cfg: TrainConfig | None = None) -> ChenNetworkStride:
    """Chen et al.'s network: length = net(SF, SV, A_max, A_min), 16 tanh hidden units."""
    cfg = cfg or TrainConfig()
    net, report = fit_network(walks, input_names=ChenNetworkStride.INPUT_NAMES, n_hidden=cfg.chen_hidden,
                              weinberg=False, cfg=cfg, weight_decay=cfg.chen_weight_decay, seed_offset=1)
    model = ChenNetworkStride(net)
    model.train_report = report
    return model


def fit_model(kind: str, walks: Sequence[Walk], cfg: TrainConfig | None = None):
    cfg = cfg or TrainConfig()
    if kind == "weinberg":
        return fit_constant(walks)
    if kind == "weinberg_bp":
        return fit_bp(walks, cfg)
    if kind == "chen_linear":
        return fit_chen_linear(walks, cfg.ridge)
    if kind == "chen_ann":
        return fit_chen_ann(walks, cfg)
    raise ValueError(f"unknown model kind {kind!r}; known: {MODEL_KINDS}")
