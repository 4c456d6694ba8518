"""Trained step-length models and their file format (Tian et al. 2014 section 3; Chen et al. 2010 section III).

Four models sit behind the one interface of :mod:`core.pdr.stride`
(``StrideModel.length_m(features)``), so the pipeline, the calibration and
the benchmark treat them alike:

==================  =========================================================  ==============================
kind                step length                                                source
==================  =========================================================  ==============================
``weinberg``        ``C * (A_max - A_min) ** (1/4)``, ``C`` constant            Weinberg; Tian eq. 4; Chen eq. 3
``weinberg_bp``     same, ``C = BP network(height, step frequency)``            Tian et al. 2014, section 3
``chen_linear``     ``a + b * SF + c * SV``                                     Chen et al. 2010, eq. 2
``chen_ann``        feed-forward network, 16 tanh hidden units,                 Chen et al. 2010, section III
                    inputs ``SF, SV, A_max, A_min``
==================  =========================================================  ==============================

(SF = step frequency 1/duration in Hz, SV = variance of the filtered
acceleration norm over the step; all features come from
:class:`core.pdr.stride.StepFeatures`.)

Inference is plain Python/numpy on one step at a time (the networks are
small: a few microseconds per step).  Training lives in the desktop tool
``tools/train_stride.py``; nothing here imports it.

File format ``pdr-stride-model`` version 1
-------------------------------------------
One JSON object (UTF-8), readable without pickle::

    {
      "format": "pdr-stride-model", "format_version": 1,
      "kind": "weinberg_bp",                  # one of KINDS
      "name": "...", "description": "...",
      "inputs": [{"name": "height_m", "unit": "m"},
                 {"name": "step_frequency_hz", "unit": "Hz"}],
      "output": {"name": "weinberg_c", "unit": "m/(m/s^2)^(1/4)"},
      "normalisation": {"mean": [...], "std": [...],       # x_norm = (x - mean) / std
                        "min": [...], "max": [...]},        # raw inputs are clipped to [min, max] first
      "output_scale": {"mean": m, "std": s},                # output = m + s * network(x_norm)
      "network": {"activation": "tanh",
                  "layers": [{"weights": [[...]], "bias": [...]},   # weights: (n_in, n_out)
                             {"weights": [[...]], "bias": [...]}]}, # last layer linear
      "output_clip": [lo, hi],                              # C (or length) is clipped to this range
      "fallback_c": 0.45,                                   # weinberg_bp: C when the height is unknown
      "length_clip_m": [0.2, 1.4],
      "placement": "waist",                                 # where the sensor was on the training walkers
      "training": {...}                                     # free-form provenance (data, CV numbers, seed)
    }

``weinberg`` files carry ``"c"`` instead of a network; ``chen_linear`` files
carry ``"coefficients": {"a": .., "b": .., "c": ..}``.  Unknown keys are
ignored; a newer ``format_version`` or an unknown ``kind`` is refused with a
:class:`StrideModelError` naming the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from core.pdr.stride import CoefficientModel, ConstantCoefficient, StepFeatures, StrideModel, WeinbergStride

FORMAT_NAME = "pdr-stride-model"
FORMAT_VERSION = 1

KINDS = ("weinberg", "weinberg_bp", "chen_linear", "chen_ann", "kubrak_velocity")

#: folder of the shipped model files (package data ``core/pdr/models/*.json``)
MODELS_DIR = Path(__file__).resolve().parent / "models"

#: the model the pipeline uses when the user gives a height (a file in MODELS_DIR, without ``.json``)
DEFAULT_MODEL_NAME = "default"

#: inputs a model may use: name -> (unit, getter from StepFeatures)
INPUTS: dict[str, tuple[str, Callable[[StepFeatures], float]]] = {
    "height_m": ("m", lambda f: math.nan if f.height_m is None else float(f.height_m)),
    "step_frequency_hz": ("Hz", lambda f: f.frequency_hz),
    "acc_var_m2_s4": ("(m/s^2)^2", lambda f: f.acc_var_m2_s4),
    "acc_max_m_s2": ("m/s^2", lambda f: f.acc_max_m_s2),
    "acc_min_m_s2": ("m/s^2", lambda f: f.acc_min_m_s2),
}

C_UNIT = "m/(m/s^2)^(1/4)"


class StrideModelError(ValueError):
    """A model file that cannot be used; the message names the file and the problem."""


def feature_matrix(features: Sequence[StepFeatures], names: Sequence[str]) -> np.ndarray:
    """Inputs ``names`` of every step, shape (n_steps, len(names)) (unknown height -> nan)."""
    getters = [INPUTS[n][1] for n in names]
    return np.array([[g(f) for g in getters] for f in features], dtype=float).reshape(len(features), len(names))


def weinberg_root(features: Sequence[StepFeatures]) -> np.ndarray:
    """``(A_max - A_min) ** (1/4)`` of every step (eq. 4), negative amplitudes taken as 0."""
    amp = np.array([f.acc_max_m_s2 - f.acc_min_m_s2 for f in features], dtype=float)
    return np.sqrt(np.sqrt(np.maximum(amp, 0.0)))


# ---------------------------------------------------------------------------
# the network


class MLP:
    """A feed-forward network: tanh hidden layers, linear output, with its input/output scaling.

    ``y = out_mean + out_std * net((clip(x, x_min, x_max) - x_mean) / x_std)``.

    Parameters
    ----------
    layers : list of (weights (n_in, n_out), bias (n_out,))
    x_mean, x_std, x_min, x_max : arrays (n_inputs,)
    out_mean, out_std : float
    """

    def __init__(self, layers, *, x_mean, x_std, x_min=None, x_max=None, out_mean=0.0, out_std=1.0):
        self.layers = [(np.asarray(w, float), np.asarray(b, float).reshape(-1)) for w, b in layers]
        if not self.layers:
            raise ValueError("a network needs at least one layer")
        n_in = self.layers[0][0].shape[0]
        for i, (w, b) in enumerate(self.layers):
            if w.ndim != 2 or w.shape[1] != b.shape[0]:
                raise ValueError(f"layer {i}: weights {w.shape} do not match bias {b.shape}")
            if i and w.shape[0] != self.layers[i - 1][0].shape[1]:
                raise ValueError(f"layer {i}: takes {w.shape[0]} inputs, previous layer gives "
                                 f"{self.layers[i - 1][0].shape[1]}")
        if self.layers[-1][0].shape[1] != 1:
            raise ValueError("the last layer must have one output")
        self.x_mean = np.asarray(x_mean, float).reshape(-1)
        self.x_std = np.asarray(x_std, float).reshape(-1)
        if self.x_mean.shape != (n_in,) or self.x_std.shape != (n_in,):
            raise ValueError(f"normalisation must have {n_in} entries")
        if not np.all(self.x_std > 0):
            raise ValueError("normalisation std must be positive")
        self.x_min = np.full(n_in, -np.inf) if x_min is None else np.asarray(x_min, float).reshape(-1)
        self.x_max = np.full(n_in, np.inf) if x_max is None else np.asarray(x_max, float).reshape(-1)
        self.out_mean = float(out_mean)
        self.out_std = float(out_std)
        self._fold()

    @property
    def n_inputs(self) -> int:
        return self.layers[0][0].shape[0]

    @property
    def hidden_sizes(self) -> list[int]:
        return [w.shape[1] for w, _ in self.layers[:-1]]

    def _fold(self):
        """Fold the input normalisation into the first layer and the output scaling into the last.

        The single-step path avoids numpy's per-call overhead where it can:
        a one-hidden-layer network with two inputs (the BP network) runs in
        plain Python (about 4 us per step on a desktop), anything larger in
        numpy (about 8 us).
        """
        w0, b0 = self.layers[0]
        w0f = w0 / self.x_std[:, None]
        b0f = b0 - (self.x_mean / self.x_std) @ w0
        layers = [(w0f, b0f)] + self.layers[1:]
        wl, bl = layers[-1]
        layers[-1] = (wl * self.out_std, bl * self.out_std + self.out_mean)
        self._folded_np = layers
        self._lo = self.x_min.tolist()
        self._hi = self.x_max.tolist()
        self._units = None
        if len(layers) == 2 and self.n_inputs == 2:
            (w1, b1), (w2, b2) = layers
            self._units = tuple((float(b), float(w), float(a0), float(a1))
                                for b, w, a0, a1 in zip(b1, w2[:, 0], w1[0], w1[1]))
            self._b_out = float(b2[0])

    def predict_one(self, x: Sequence[float]) -> float:
        """The output for one input vector (raw units)."""
        if self._units is not None:
            lo, hi = self._lo, self._hi
            x0 = min(max(x[0], lo[0]), hi[0])
            x1 = min(max(x[1], lo[1]), hi[1])
            th = math.tanh
            return self._b_out + sum(w * th(b + a0 * x0 + a1 * x1) for b, w, a0, a1 in self._units)
        h = np.minimum(np.maximum(np.array(x, dtype=float), self.x_min), self.x_max)
        last = len(self._folded_np) - 1
        for k, (w, b) in enumerate(self._folded_np):
            h = h @ w + b
            if k != last:
                h = np.tanh(h)
        return float(h[0])

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Outputs for a batch ``x`` (n, n_inputs) in raw units; returns (n,)."""
        h = np.clip(np.asarray(x, float).reshape(-1, self.n_inputs), self.x_min, self.x_max)
        last = len(self._folded_np) - 1
        for k, (w, b) in enumerate(self._folded_np):
            h = h @ w + b
            if k != last:
                h = np.tanh(h)
        return h[:, 0]

    # -- file representation ------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "normalisation": {"mean": self.x_mean.tolist(), "std": self.x_std.tolist(),
                              "min": [None if not math.isfinite(v) else v for v in self.x_min.tolist()],
                              "max": [None if not math.isfinite(v) else v for v in self.x_max.tolist()]},
            "output_scale": {"mean": self.out_mean, "std": self.out_std},
            "network": {"activation": "tanh",
                        "layers": [{"weights": w.tolist(), "bias": b.tolist()} for w, b in self.layers]},
        }

    @classmethod
    def from_dict(cls, d: dict) -> "MLP":
        net = d["network"]
        if net.get("activation", "tanh") != "tanh":
            raise ValueError(f"unsupported activation {net.get('activation')!r} (only tanh)")
        norm = d["normalisation"]
        n = len(norm["mean"])

        def bound(key, default):
            vals = norm.get(key) or [None] * n
            return [default if v is None else float(v) for v in vals]

        return cls([(layer["weights"], layer["bias"]) for layer in net["layers"]],
                   x_mean=norm["mean"], x_std=norm["std"], x_min=bound("min", -np.inf), x_max=bound("max", np.inf),
                   out_mean=d.get("output_scale", {}).get("mean", 0.0),
                   out_std=d.get("output_scale", {}).get("std", 1.0))


# ---------------------------------------------------------------------------
# models


class _Clip:
    def __init__(self, min_length_m: float, max_length_m: float):
        if not 0 <= min_length_m < max_length_m:
            raise ValueError(f"bad length range [{min_length_m}, {max_length_m}]")
        self.min_length_m = float(min_length_m)
        self.max_length_m = float(max_length_m)

    def _clip(self, length: float) -> float:
        return min(max(length, self.min_length_m), self.max_length_m)

    def _clip_np(self, lengths: np.ndarray) -> np.ndarray:
        return np.clip(lengths, self.min_length_m, self.max_length_m)


class NetworkCoefficient(CoefficientModel):
    """Weinberg's ``C`` from a BP network of the walker's height and the step frequency (Tian et al. 2014).

    Parameters
    ----------
    net : MLP
        Inputs ``input_names`` (default height_m, step_frequency_hz), output C.
    c_range : (float, float)
        The network's C is clipped to this range.
    fallback_c : float
        C used for a step whose ``height_m`` is unknown (None); the constant C
        fitted on the same training data.
    height_m : float or None
        Height used when the step carries none (e.g. from the user's profile).
    """

    name = "bp-network"

    def __init__(self, net: MLP, *, input_names: Sequence[str] = ("height_m", "step_frequency_hz"),
                 c_range: tuple[float, float] = (0.2, 0.9), fallback_c: float = 0.45,
                 height_m: float | None = None):
        for n in input_names:
            if n not in INPUTS:
                raise ValueError(f"unknown input {n!r}; known: {sorted(INPUTS)}")
        if net.n_inputs != len(input_names):
            raise ValueError(f"network takes {net.n_inputs} inputs, {len(input_names)} named")
        self.net = net
        self.input_names = tuple(input_names)
        self._getters = [INPUTS[n][1] for n in self.input_names]
        self._needs_height = "height_m" in self.input_names
        self._standard = self.input_names == ("height_m", "step_frequency_hz")
        self.c_range = (float(c_range[0]), float(c_range[1]))
        self.fallback_c = float(fallback_c)
        self.height_m = None if height_m is None else float(height_m)

    def coefficient(self, f: StepFeatures) -> float:
        if self._needs_height and f.height_m is None:
            if self.height_m is None:
                return self.fallback_c
            f = dataclasses.replace(f, height_m=self.height_m)
        if self._standard:
            c = self.net.predict_one((f.height_m, f.frequency_hz))
        else:
            c = self.net.predict_one([g(f) for g in self._getters])
        return min(max(c, self.c_range[0]), self.c_range[1])

    def coefficients(self, features: Sequence[StepFeatures]) -> np.ndarray:
        """C of every step (batch form of :meth:`coefficient`, same numbers)."""
        x = feature_matrix(features, self.input_names)
        c = np.full(len(features), self.fallback_c)
        if self._needs_height:
            j = self.input_names.index("height_m")
            if self.height_m is not None:
                x[np.isnan(x[:, j]), j] = self.height_m
            ok = ~np.isnan(x[:, j])
        else:
            ok = np.ones(len(features), bool)
        if ok.any():
            c[ok] = np.clip(self.net.predict(x[ok]), *self.c_range)
        return c


class ScaledCoefficient(CoefficientModel):
    """A per-user factor on another coefficient model's C (the result of a calibration walk)."""

    name = "scaled"

    def __init__(self, base: CoefficientModel, scale: float):
        if not (scale > 0 and math.isfinite(scale)):
            raise ValueError(f"scale must be a positive number, got {scale}")
        self.base = base
        self.scale = float(scale)

    def coefficient(self, f: StepFeatures) -> float:
        return self.scale * self.base.coefficient(f)

    def coefficients(self, features):
        return self.scale * coefficients_of(self.base, features)


def coefficients_of(cm: CoefficientModel, features: Sequence[StepFeatures]) -> np.ndarray:
    """C of every step for any coefficient model (uses a batch method when it has one)."""
    if hasattr(cm, "coefficients"):
        return np.asarray(cm.coefficients(features), float)
    return np.array([cm.coefficient(f) for f in features], float)


class ChenLinearStride(_Clip, StrideModel):
    """Chen et al. 2010, eq. 2: ``length = a + b * SF + c * SV`` (SF in Hz, SV in (m/s^2)^2)."""

    name = "chen-linear"

    def __init__(self, *, a: float, b: float, c: float, min_length_m: float = 0.2, max_length_m: float = 1.4,
                 scale: float = 1.0):
        super().__init__(min_length_m, max_length_m)
        self.a, self.b, self.c = float(a), float(b), float(c)
        self.scale = float(scale)

    def length_m(self, f: StepFeatures) -> float:
        return self._clip(self.scale * (self.a + self.b * f.frequency_hz + self.c * f.acc_var_m2_s4))

    def lengths_m(self, features: Sequence[StepFeatures]) -> np.ndarray:
        x = feature_matrix(features, ("step_frequency_hz", "acc_var_m2_s4"))
        return self._clip_np(self.scale * (self.a + self.b * x[:, 0] + self.c * x[:, 1]))


class ChenNetworkStride(_Clip, StrideModel):
    """Chen et al. 2010: feed-forward network (16 tanh hidden units) of SF, SV, A_max, A_min -> length."""

    name = "chen-ann"
    INPUT_NAMES = ("step_frequency_hz", "acc_var_m2_s4", "acc_max_m_s2", "acc_min_m_s2")

    def __init__(self, net: MLP, *, min_length_m: float = 0.2, max_length_m: float = 1.4, scale: float = 1.0):
        super().__init__(min_length_m, max_length_m)
        if net.n_inputs != len(self.INPUT_NAMES):
            raise ValueError(f"Chen's network takes {len(self.INPUT_NAMES)} inputs, got {net.n_inputs}")
        self.net = net
        self.scale = float(scale)

    def length_m(self, f: StepFeatures) -> float:
        x = (f.frequency_hz, f.acc_var_m2_s4, f.acc_max_m_s2, f.acc_min_m_s2)
        return self._clip(self.scale * self.net.predict_one(x))

    def lengths_m(self, features: Sequence[StepFeatures]) -> np.ndarray:
        return self._clip_np(self.scale * self.net.predict(feature_matrix(features, self.INPUT_NAMES)))


class ScaledStride(StrideModel):
    """Any stride model times a per-user factor (used for models without a ``scale`` of their own)."""

    name = "scaled"

    def __init__(self, base: StrideModel, scale: float):
        if not (scale > 0 and math.isfinite(scale)):
            raise ValueError(f"scale must be a positive number, got {scale}")
        self.base = base
        self.scale = float(scale)

    def length_m(self, f: StepFeatures) -> float:
        return self.scale * self.base.length_m(f)

    def lengths_m(self, features):
        return self.scale * lengths_of(self.base, features)


def lengths_of(model: StrideModel, features: Sequence[StepFeatures]) -> np.ndarray:
    """Step lengths of every step (batch; equal to calling ``model.length_m`` step by step)."""
    features = list(features)
    if hasattr(model, "lengths_m"):
        return np.asarray(model.lengths_m(features), float)
    if isinstance(model, WeinbergStride):
        c = coefficients_of(model.coefficient, features)
        return np.clip(c * weinberg_root(features), model.min_length_m, model.max_length_m)
    return np.array([model.length_m(f) for f in features], float)


def with_scale(model: StrideModel, scale: float) -> StrideModel:
    """``model`` with every step length multiplied by ``scale`` (before the model's own clipping).

    Weinberg models get a :class:`ScaledCoefficient` (the calibration refines
    C itself); the Chen models their ``scale``; anything else a
    :class:`ScaledStride`.  The input model is not modified.
    """
    if not (scale > 0 and math.isfinite(scale)):
        raise ValueError(f"scale must be a positive number, got {scale}")
    if isinstance(model, WeinbergStride):
        out = WeinbergStride(coefficient=ScaledCoefficient(model.coefficient, scale),
                             min_length_m=model.min_length_m, max_length_m=model.max_length_m)
        _copy_meta(model, out)
        return out
    if isinstance(model, ChenLinearStride):
        out = ChenLinearStride(a=model.a, b=model.b, c=model.c, min_length_m=model.min_length_m,
                               max_length_m=model.max_length_m, scale=model.scale * scale)
        _copy_meta(model, out)
        return out
    if isinstance(model, ChenNetworkStride):
        out = ChenNetworkStride(model.net, min_length_m=model.min_length_m, max_length_m=model.max_length_m,
                                scale=model.scale * scale)
        _copy_meta(model, out)
        return out
    return ScaledStride(model, scale)


def _copy_meta(src, dst):
    for k in ("kind", "model_id", "meta"):
        if hasattr(src, k):
            setattr(dst, k, getattr(src, k))


# ---------------------------------------------------------------------------
# file format


def model_to_dict(model: StrideModel, **meta) -> dict:
    """The file representation of ``model`` (see the module docstring); ``meta`` adds top-level keys."""
    d: dict = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION}
    if isinstance(model, WeinbergStride) and isinstance(model.coefficient, ConstantCoefficient):
        d.update(kind="weinberg", inputs=[{"name": "acc_max_m_s2", "unit": "m/s^2"},
                                          {"name": "acc_min_m_s2", "unit": "m/s^2"}],
                 output={"name": "step_length_m", "unit": "m"}, c=model.coefficient.c, c_unit=C_UNIT)
    elif isinstance(model, WeinbergStride) and isinstance(model.coefficient, NetworkCoefficient):
        cm = model.coefficient
        d.update(kind="weinberg_bp", inputs=[{"name": n, "unit": INPUTS[n][0]} for n in cm.input_names],
                 output={"name": "weinberg_c", "unit": C_UNIT}, **cm.net.to_dict(),
                 output_clip=list(cm.c_range), fallback_c=cm.fallback_c)
    elif isinstance(model, ChenLinearStride):
        if model.scale != 1.0:
            raise ValueError("save the unscaled model; per-user scales live in the user profile")
        d.update(kind="chen_linear", inputs=[{"name": "step_frequency_hz", "unit": "Hz"},
                                             {"name": "acc_var_m2_s4", "unit": "(m/s^2)^2"}],
                 output={"name": "step_length_m", "unit": "m"},
                 coefficients={"a": model.a, "b": model.b, "c": model.c},
                 coefficient_units={"a": "m", "b": "m/Hz", "c": "m/(m/s^2)^2"})
    elif isinstance(model, ChenNetworkStride):
        if model.scale != 1.0:
            raise ValueError("save the unscaled model; per-user scales live in the user profile")
        d.update(kind="chen_ann", inputs=[{"name": n, "unit": INPUTS[n][0]} for n in model.INPUT_NAMES],
                 output={"name": "step_length_m", "unit": "m"}, **model.net.to_dict())
    else:
        raise ValueError(f"cannot save a {type(model).__name__} (only the models of core.pdr.stride_models)")
    d["length_clip_m"] = [model.min_length_m, model.max_length_m]
    d.update(meta)
    return d


def model_from_dict(d: dict, source: str = "<dict>") -> StrideModel:
    """Build the model a file describes; :class:`StrideModelError` for anything wrong."""
    try:
        if d.get("format") != FORMAT_NAME:
            raise StrideModelError(f"not a {FORMAT_NAME} file (format={d.get('format')!r})")
        ver = d.get("format_version")
        if not isinstance(ver, int) or ver < 1 or ver > FORMAT_VERSION:
            raise StrideModelError(f"format_version {ver!r} not supported (this reader knows 1..{FORMAT_VERSION})")
        kind = d.get("kind")
        if kind not in KINDS:
            raise StrideModelError(f"unknown model kind {kind!r}; known: {', '.join(KINDS)}")
        lo, hi = d.get("length_clip_m", [0.2, 1.4])
        names = tuple(i["name"] for i in d.get("inputs", []))
        for n in names:
            if n not in INPUTS:
                raise StrideModelError(f"unknown input {n!r}")
            unit = next(i.get("unit") for i in d["inputs"] if i["name"] == n)
            if unit is not None and unit != INPUTS[n][0]:
                raise StrideModelError(f"input {n!r} in unit {unit!r}, expected {INPUTS[n][0]!r}")
        if kind == "weinberg":
            model: StrideModel = WeinbergStride(coefficient=float(d["c"]), min_length_m=lo, max_length_m=hi)
        elif kind == "weinberg_bp":
            cm = NetworkCoefficient(MLP.from_dict(d), input_names=names,
                                    c_range=tuple(d.get("output_clip", (0.2, 0.9))),
                                    fallback_c=float(d["fallback_c"]))
            model = WeinbergStride(coefficient=cm, min_length_m=lo, max_length_m=hi)
        elif kind == "kubrak_velocity":
            from core.pdr.velocity import VelocityModel, VelocityStride  # noqa: PLC0415 - velocity imports stride
            model = VelocityStride(VelocityModel.from_dict(d))
        elif kind == "chen_linear":
            k = d["coefficients"]
            model = ChenLinearStride(a=k["a"], b=k["b"], c=k["c"], min_length_m=lo, max_length_m=hi)
        else:
            if names != ChenNetworkStride.INPUT_NAMES:
                raise StrideModelError(f"chen_ann inputs must be {ChenNetworkStride.INPUT_NAMES}, got {names}")
            model = ChenNetworkStride(MLP.from_dict(d), min_length_m=lo, max_length_m=hi)
    except StrideModelError as e:
        raise StrideModelError(f"{source}: {e}") from None
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise StrideModelError(f"{source}: malformed {d.get('kind', '')} model: {e!r}") from None
    model.kind = kind
    model.model_id = f"{d.get('name') or kind}@{d.get('created', '')}"
    model.meta = {k: v for k, v in d.items() if k in ("name", "description", "placement", "training", "created")}
    return model


def save_stride_model(model: StrideModel, path: str | Path, **meta) -> dict:
    """Write ``model`` as a ``pdr-stride-model`` JSON file; returns the dict written."""
    d = model_to_dict(model, **meta)
    text = json.dumps(d, indent=1, allow_nan=False)
    Path(path).write_text(text + "\n", encoding="utf-8")
    return d


def resolve_model_path(path_or_name: str | Path) -> Path:
    """A file path as given, or a shipped model's name (``"default"``, ``"weinberg_bp"``, ...)."""
    p = Path(path_or_name)
    if p.suffix == ".json" or p.exists() or len(p.parts) > 1:
        return p
    name = DEFAULT_MODEL_NAME if str(path_or_name) == "default" else str(path_or_name)
    return MODELS_DIR / f"{name}.json"


def load_stride_model(path_or_name: str | Path = "default") -> StrideModel:
    """A stride model from a ``pdr-stride-model`` JSON file or a shipped model name.

    ``"default"`` is the model the pipeline uses when the user gives a
    height; :func:`shipped_models` lists the others.
    """
    p = resolve_model_path(path_or_name)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        have = ", ".join(shipped_models()) or "none"
        raise StrideModelError(f"{p}: no such model file (shipped models: {have})") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise StrideModelError(f"{p}: not JSON: {e}") from None
    if not isinstance(d, dict):
        raise StrideModelError(f"{p}: not a JSON object")
    return model_from_dict(d, source=str(p))


def shipped_models() -> list[str]:
    """Names of the model files shipped in ``core/pdr/models``."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.json")) if MODELS_DIR.is_dir() else []
