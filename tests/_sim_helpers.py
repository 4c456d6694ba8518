"""Simulated walks changed after the fact (tests only)."""

from __future__ import annotations

import numpy as np

from core.recording import Recording, Stream


def scale_acc_motion(rec: Recording, spans, scale: float) -> Recording:
    """``rec`` with the accelerometer's motion scaled by ``scale`` in each span: ``spans`` is a list of
    ``(mask over the acc samples, the reading the motion is taken about)``; the other streams are shared."""
    acc = rec.streams["acc"]
    v = acc.values.copy()
    for mask, rest in spans:
        v[mask] = rest + scale * (v[mask] - rest)
    streams = dict(rec.streams)
    streams["acc"] = Stream("acc", acc.t_ns, v, acc.columns, acc.unit, acc.note)
    return Recording(streams, dict(rec.device), dict(rec.metadata))
