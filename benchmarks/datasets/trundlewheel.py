"""Trundle-wheel walks (Jeremy618/TrundleWheel): phone web-API motion + a wheel ticking every metre.

Folder ``trundlewheel_distance/`` under the data root (see its README.md).
Only the two **raw** logs (``raw/*.csv.gz``, about 400 m each, one user) are
usable for step detection; the authors' 1 Hz "conditioned" files are too
coarse and are not read here.

Raw format: ``;``-separated, one event type per row, ``time`` in ms since the
start of the recording (the app's clock; arrival times of a web app, so they
jitter by a few ms).  What the reader makes of it:

* ``acc`` = W3C DeviceMotion ``accelerationIncludingGravity`` (``m_accG_*``),
  m/s^2, 0.1 m/s^2 resolution, about 59 Hz.  Chrome on Android reports it in
  the Android device axes with the Android sign (flat, screen up: z = +g;
  checked on the still phone at the end of the walks).
* ``gyro`` = ``rotationRate`` converted deg/s -> rad/s; W3C ``alpha`` is about
  z, ``beta`` about x, ``gamma`` about y.
* no magnetometer; the GNSS rows carry Unix-epoch times that cannot be tied
  to the ``time`` clock reliably, so no ``gps`` stream.
* ground truth: the wheel's cumulative metre ticks (``distance`` rows) as
  ``wheel_t_ns`` / ``wheel_m``; ``distance_m`` is the last tick (the wheel
  total the authors report).  The phone's own step counter goes to
  ``peer_step_counts["phone"]``.

Placement is not documented.  The signals say it was not a steady
"texting" hold: the mean acceleration norm is 11-12 m/s^2 for minutes at a
time (centripetal acceleration of a swinging arm or a pocket), and the
gravity direction moves between the x and z axes.  We label it
``"unknown (swinging hand or pocket?)"``.  One walker, height unknown.
"""

from __future__ import annotations

import gzip
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from core.conventions import ACC, GYRO
from core.recording import Recording, make_stream, repair_recording

NAME = "trundlewheel_distance"

_FILES = ("normal_speed_valid", "mix_of_everything_valid")


@dataclass
class TrundleTrial(Trial):
    """A :class:`Trial` with the wheel's metre ticks."""

    #: time of each wheel tick (t_ns on the recording clock) and the cumulative distance there (m)
    wheel_t_ns: np.ndarray | None = None
    wheel_m: np.ndarray | None = None


def available(root: Path) -> bool:
    return any((Path(root) / NAME / "raw" / f"{n}.csv.gz").exists() for n in _FILES)


def _parse(path: Path) -> dict:
    with gzip.open(path, "rt") as fh:
        header = fh.readline().rstrip("\n").split(";")
        col = {name: i for i, name in enumerate(header)}
        need = ["time", "m_accG_x", "m_accG_y", "m_accG_z", "m_rotTate_alpha", "m_rotTate_beta",
                "m_rotTate_gamma", "steps", "distance"]
        missing = [n for n in need if n not in col]
        if missing:
            raise ValueError(f"{path}: columns missing: {missing}")
        acc, rot, steps, dist, first = [], [], [], [], None
        for line in fh:
            c = line.rstrip("\n").split(";")
            if len(c) < len(header):
                c += [""] * (len(header) - len(c))
            if first is None:
                first = c
            if c[col["p_lat"]] if "p_lat" in col else "":
                continue  # GNSS rows: epoch-ms clock, not read
            t = float(c[col["time"]])
            if c[col["m_accG_x"]]:
                acc.append((t, float(c[col["m_accG_x"]]), float(c[col["m_accG_y"]]), float(c[col["m_accG_z"]])))
            if c[col["m_rotTate_alpha"]]:
                rot.append((t, float(c[col["m_rotTate_beta"]]), float(c[col["m_rotTate_gamma"]]),
                            float(c[col["m_rotTate_alpha"]])))
            if c[col["steps"]]:
                steps.append((t, float(c[col["steps"]])))
            if c[col["distance"]]:
                dist.append((t, float(c[col["distance"]])))
    info = {}
    for k in ("duration", "date", "total_distance", "total_steps", "device_os", "device_model"):
        if k in col and first is not None:
            info[k] = first[col[k]]
    return {"acc": np.array(acc, float).reshape(-1, 4), "rot": np.array(rot, float).reshape(-1, 4),
            "steps": np.array(steps, float).reshape(-1, 2), "dist": np.array(dist, float).reshape(-1, 2),
            "info": info}


def _ms_to_ns(ms: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(ms, float) * 1e6).astype(np.int64)


def load_recording(path: Path) -> Recording:
    p = _parse(Path(path))
    streams = {ACC: make_stream(ACC, _ms_to_ns(p["acc"][:, 0]), p["acc"][:, 1:4],
                                note="W3C DeviceMotion accelerationIncludingGravity, 0.1 m/s^2 resolution")}
    if len(p["rot"]):
        streams[GYRO] = make_stream(GYRO, _ms_to_ns(p["rot"][:, 0]), np.radians(p["rot"][:, 1:4]),
                                    note="W3C rotationRate (beta, gamma, alpha) converted to rad/s")
    rec = Recording(streams=streams,
                    device={"model": p["info"].get("device_model", ""), "os": p["info"].get("device_os", ""),
                            "api": "W3C DeviceMotion (web app)"},
                    metadata={"dataset": NAME}, source=str(path))
    return repair_recording(rec, warn=False)


def _trial(path: Path) -> TrundleTrial:
    p = _parse(path)
    d = p["dist"]
    total = float(d[-1, 1]) if len(d) else math.nan
    phone_steps = int(p["steps"][-1, 1]) if len(p["steps"]) else None
    name = path.name.replace(".csv.gz", "")
    return TrundleTrial(
        dataset=NAME,
        name=name,
        load=lambda q=path: load_recording(q),
        placement="unknown (swinging hand or pocket?)",
        distance_m=total,
        subject={"id": "trundle-jeremy", "height_m": None},
        peer_step_counts={"phone": phone_steps} if phone_steps is not None else {},
        notes="one walker, ~400 m outdoors (Malmo), web DeviceMotion ~59 Hz, no magnetometer; "
              "distance from a trundle wheel (1 m ticks)",
        wheel_t_ns=_ms_to_ns(d[:, 0]) if len(d) else None,
        wheel_m=d[:, 1].copy() if len(d) else None,
    )


def trials(root: Path) -> list[TrundleTrial]:
    folder = Path(root) / NAME / "raw"
    return [_trial(folder / f"{n}.csv.gz") for n in _FILES if (folder / f"{n}.csv.gz").exists()]
