"""A learned stance detector (issue #27): logistic regression on about 1 s of IMU samples.

Features of sample k (all from centred windows in **seconds**, so a model means
the same at 100 and 400 Hz; :func:`features`):

``log10 SHOE(w)``
    the SHOE statistic (:func:`core.foot.stance.statistic`, its default noise
    settings) over windows ``w`` of :data:`SHOE_WINDOWS_S`;
``log10 SHOE / floor``
    the short-window statistic over its moving minimum across ``floor_window_s``
    (the adaptive threshold's quantity: how far above its own floor);
``log10 SHOE min / max``
    its minimum and maximum over ``context_s`` around k (is k inside a quiet run);
``log10 |w|^2``, ``| |a| - g |``
    angular-rate energy and the mean deviation of the specific force's norm
    from gravity over the short window.

The model (:class:`StanceModel`, a JSON file in ``core/foot/models/``): the
features are standardised by the file's mean and sd, then
``p(stance) = sigmoid(b + w . z)`` (a logistic regression; ``hidden`` layers of
tanh units before it when the file has them).  Inference is numpy only and
deterministic.  Labels of the training: the foot's VICON speed below a fixed
speed (``benchmarks.foot.vicon_still``, 0.05 m/s), on the PyShoe tuning split
only; training and the choice of the decision threshold:
``benchmarks/foot_stance_model.py`` (seeded, reproducible).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from core.conventions import STANDARD_GRAVITY_M_S2

MODELS_DIR = Path(__file__).resolve().parent / "models"
#: the model file ``detector="learned"`` uses by default (in :data:`MODELS_DIR`, without ``.json``)
DEFAULT_MODEL = "stance_lr"
FORMAT = "pdr-stance-model"

#: SHOE windows of the features (s)
SHOE_WINDOWS_S = (0.05, 0.1, 0.3)
FEATURE_NAMES = ("log10_shoe_0p05s", "log10_shoe_0p1s", "log10_shoe_0p3s", "log10_shoe_over_floor",
                 "log10_shoe_context_min", "log10_shoe_context_max", "log10_gyro_energy", "acc_norm_dev_m_s2")


@dataclass(frozen=True)
class FeatureSettings:
    """The windows of :func:`features` (s); a model file stores the ones it was trained with."""

    floor_window_s: float = 1.0
    context_s: float = 0.4

    @property
    def span_s(self) -> float:
        """How far (s) the features of a sample reach before and after it."""
        return max(max(SHOE_WINDOWS_S), 0.1 + self.floor_window_s, 0.1 + self.context_s) / 2


def _bounds(t_ns, width_s: float):
    t = np.asarray(t_ns, dtype=np.int64)
    h = int(round(width_s * 0.5e9))
    return np.searchsorted(t, t - h, side="left"), np.searchsorted(t, t + h, side="right")


def features(t_ns, acc_b, gyro_b, fs: FeatureSettings | None = None) -> np.ndarray:
    """The feature matrix ``(n, len(FEATURE_NAMES))`` of simultaneous accelerometer / gyroscope rows."""
    from core.foot.stance import StanceSettings, _wsum, statistic, window_min

    fs = fs or FeatureSettings()
    t = np.asarray(t_ns, dtype=np.int64)
    acc = np.asarray(acc_b, dtype=float).reshape(-1, 3)
    gyr = np.asarray(gyro_b, dtype=float).reshape(-1, 3)
    n = len(t)
    if n == 0:
        return np.zeros((0, len(FEATURE_NAMES)))
    tiny = 1e-12
    shoe = [np.log10(np.maximum(statistic(StanceSettings(detector="shoe", window_s=w), t, acc, gyr), tiny))
            for w in SHOE_WINDOWS_S]
    s1 = shoe[1]
    lo, hi = _bounds(t, fs.floor_window_s)
    over_floor = s1 - window_min(s1, lo, hi)
    lo, hi = _bounds(t, fs.context_s)
    ctx_min = window_min(s1, lo, hi)
    ctx_max = -window_min(-s1, lo, hi)
    lo, hi = _bounds(t, 0.1)
    cnt = (hi - lo).astype(float)
    energy = np.log10(np.maximum(_wsum(np.einsum("ij,ij->i", gyr, gyr), lo, hi) / cnt, tiny))
    dev = _wsum(np.abs(np.linalg.norm(acc, axis=1) - STANDARD_GRAVITY_M_S2), lo, hi) / cnt
    x = np.column_stack(shoe + [over_floor, ctx_min, ctx_max, energy, dev])
    return np.where(np.isfinite(x), x, 0.0)


@dataclass(frozen=True)
class StanceModel:
    """Standardisation, optional tanh hidden layers and a logistic output (see the module docstring)."""

    mean: np.ndarray
    sd: np.ndarray
    #: ``[(W (n_in, n_out), b (n_out,)), ...]``: tanh hidden layers, then the logistic output layer (n_out 1)
    layers: tuple
    #: stance when p(stance) >= this
    threshold_p: float
    feature_settings: FeatureSettings
    name: str = ""
    meta: dict | None = None

    def probability(self, x) -> np.ndarray:
        """p(stance) of feature rows ``x (n, m)``."""
        z = (np.asarray(x, dtype=float) - self.mean) / self.sd
        for W, b in self.layers[:-1]:
            z = np.tanh(z @ W + b)
        W, b = self.layers[-1]
        logit = np.clip((z @ W + b)[:, 0], -50.0, 50.0)
        return 1.0 / (1.0 + np.exp(-logit))

    def to_json(self) -> dict:
        return {"format": FORMAT, "format_version": 1, "features": list(FEATURE_NAMES),
                "feature_settings": {"floor_window_s": self.feature_settings.floor_window_s,
                                     "context_s": self.feature_settings.context_s},
                "normalisation": {"mean": self.mean.tolist(), "sd": self.sd.tolist()},
                "layers": [{"weights": np.asarray(W).tolist(), "bias": np.asarray(b).tolist()}
                           for W, b in self.layers],
                "hidden_activation": "tanh", "output": "logistic p(stance)",
                "threshold_p": self.threshold_p, "meta": self.meta or {}}

    @classmethod
    def from_json(cls, d: dict, name: str = "") -> "StanceModel":
        if d.get("format") != FORMAT:
            raise ValueError(f"not a stance model file (format {d.get('format')!r}, expected {FORMAT!r})")
        if list(d["features"]) != list(FEATURE_NAMES):
            raise ValueError(f"stance model {name!r} has features {d['features']}, this code {list(FEATURE_NAMES)}")
        layers = tuple((np.asarray(L["weights"], dtype=float), np.asarray(L["bias"], dtype=float))
                       for L in d["layers"])
        fs = FeatureSettings(**d["feature_settings"])
        return cls(np.asarray(d["normalisation"]["mean"], dtype=float),
                   np.asarray(d["normalisation"]["sd"], dtype=float), layers, float(d["threshold_p"]), fs,
                   name, d.get("meta", {}))


@lru_cache(maxsize=8)
def load_model(name: str = DEFAULT_MODEL) -> StanceModel:
    """A model file from :data:`MODELS_DIR` by name, or a path to a ``.json`` file."""
    p = Path(name)
    if p.suffix != ".json":
        p = MODELS_DIR / f"{name}.json"
    if not p.is_file():
        raise FileNotFoundError(f"no stance model {name!r} ({p})")
    return StanceModel.from_json(json.loads(p.read_text()), name=str(name))


def motion_probability(model: StanceModel, t_ns, acc_b, gyro_b) -> np.ndarray:
    """``1 - p(stance)`` of every sample: the "learned" detector's statistic (stance when <= 1 - threshold_p)."""
    x = features(t_ns, acc_b, gyro_b, model.feature_settings)
    if len(x) == 0:
        return np.zeros(0)
    p = model.probability(x)
    return 1.0 - p if np.all(np.isfinite(p)) else np.where(np.isfinite(p), 1.0 - p, math.inf)
