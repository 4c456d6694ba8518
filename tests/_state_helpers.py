"""What a reset test compares: the plain values an object holds (nan equal to nan)."""

from __future__ import annotations

import math

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
