"""What a state or reset test compares: where two objects differ in value, and the plain values an object holds."""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque

import numpy as np

_PLAIN = (bool, int, float, str, type(None))


def _key(v):
    return "nan" if isinstance(v, float) and math.isnan(v) else v


def scalar_attributes(obj) -> dict:
    """``vars(obj)`` restricted to plain values (and tuples of them), nan made comparable."""
    out = {}
    for k, v in vars(obj).items():
        if isinstance(v, _PLAIN):
            out[k] = _key(v)
        elif isinstance(v, tuple) and all(isinstance(x, _PLAIN) for x in v):
            out[k] = tuple(_key(x) for x in v)
    return out


def differences(a, b, path="", seen=None) -> list:
    """Where ``a`` and ``b`` differ in value (attributes, slots, dataclass fields, containers, arrays by their bytes,
    nan equal to nan): a list of paths, empty when equal."""
    seen = set() if seen is None else seen
    if type(a) is not type(b):
        return [f"{path}: {type(a).__name__} != {type(b).__name__}"]
    if isinstance(a, np.ndarray):
        return [] if a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes() else [path]
    if isinstance(a, float):
        return [] if a == b or (math.isnan(a) and math.isnan(b)) else [f"{path}: {a} != {b}"]
    if a is None or isinstance(a, (bool, int, str, bytes, enum.Enum, type)) or callable(a):
        return [] if a == b or callable(a) else [f"{path}: {a!r} != {b!r}"]
    if (id(a), id(b)) in seen:
        return []
    seen.add((id(a), id(b)))
    if isinstance(a, dict):
        if list(a) != list(b):
            return [f"{path}: keys {list(a)} != {list(b)}"]
        return [d for k in a for d in differences(a[k], b[k], f"{path}[{k!r}]", seen)]
    if isinstance(a, (list, tuple, deque)):
        if len(a) != len(b) or (isinstance(a, deque) and a.maxlen != b.maxlen):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{i}]", seen)]
    names = [f.name for f in dataclasses.fields(a)] if dataclasses.is_dataclass(a) else []
    names += [n for n in getattr(a, "__dict__", {}) if n not in names]
    names += [n for c in type(a).__mro__ for n in getattr(c, "__slots__", ()) if n not in names and hasattr(a, n)]
    if not names:
        return [] if a == b else [f"{path}: {a!r} != {b!r}"]
    return [d for n in names for d in differences(getattr(a, n), getattr(b, n), f"{path}.{n}", seen)]
