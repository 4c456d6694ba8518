"""Reader for PyShoe's processed trials (University of Toronto foot-mounted inertial navigation dataset).

Wagstaff, Peretroukhin & Kelly's dataset (IEEE DataPort, doi:10.21227/v1z6-9z84), processed by their
``pyshoe`` code: one MATLAB level-5 MAT-file per trial (here also gzip), read with
:mod:`core.importers.matv5` (numpy + zlib: no scipy on the phone).

Format
======
Variables (MATLAB shapes)::

    imu   N x 6   ax ay az (m/s^2) gx gy gz (rad/s), sensor axes (z down: at rest a = (0, 0, -g))
    ts    1 x N   time (s)
    gt    N x 3   VICON position of the foot at every IMU sample (m)             [VICON trials]
    zv_<detector>_opt   1 x N   zero-velocity labels (1 = still) of the detectors shoe, ared, amvd,
                                mbgtd, vicon, each at its per-trial optimal threshold
    G_<detector>_opt    1 x 1   that threshold
    trial_error 1 x 5   PyShoe's error (m) per detector (order shoe, ared, amvd, mbgtd, vicon)
    best_detector (char), best_error 1 x 1

``imu`` and ``ts`` are required; the rest is read when present.  The sensor
(a LORD MicroStrain 3DM-GX3-25 at 200 Hz) is on the foot: the recording
declares ``device["placement"] = "foot"`` (so ``pdr replay`` runs foot mode).

Streams
=======
* ``acc``, ``gyro``: ``imu`` copied (already m/s^2 and rad/s), ``t_ns =
  round(ts * 1e9)`` (the file's clock; absolute time unknown).  Sensor axes
  (z down), not the Android device axes: the foot filter does not need them.
* ``posi`` (ground truth, columns ``east_m, north_m, up_m``): the VICON
  position at every sample.  ``gt`` has z up (the foot rises in the swing)
  but its horizontal axes are mirrored against a right-handed z-up frame:
  read as ``(x, y, z)`` a track fits only as a mirror image, so ENU is
  ``(y, x, z)`` (checked on the dataset's first tuning trial).  A dense
  position track: :func:`core.metrics.truth_of` takes it as landmarks.
* ``zero_velocity`` (reference labels, one column per detector present, in
  the order of :data:`DETECTORS`): the ``zv_*_opt`` labels, 1 still, 0 moving.
  They are each at a threshold chosen per trial for the smallest error, not
  a stance truth.

``metadata``: ``pyshoe_thresholds`` (detector -> ``G_*_opt``),
``pyshoe_errors_m`` (detector -> ``trial_error``), ``pyshoe_best``
(``[detector, error]``) when the file has them.

A file without ``imu``/``ts``, with shapes that do not fit (``imu`` not N x 6,
``ts`` not N values, ``gt`` not N x 3), with times that are not finite, or a
MAT-file this reader cannot read is a :class:`RecordingError` naming the file.
"""

from __future__ import annotations

import numpy as np

from core.conventions import ACC, GYRO
from core.recording import MAX_UNCOMPRESSED_BYTES, Recording, RecordingError, make_stream
from core.importers import matv5
from core.importers._common import EXTRA_STREAM_SPECS, POSI, ZERO_VELOCITY, finish, first_bad_time, open_binary

FORMAT = "pyshoe"

#: PyShoe's detectors, in the order of the files' ``trial_error``
DETECTORS = ("shoe", "ared", "amvd", "mbgtd", "vicon")
REQUIRED = ("imu", "ts")
#: ``posi`` columns of the VICON positions
POSI_COLUMNS = ["east_m", "north_m", "up_m"]


def looks_like(mat_names) -> bool:
    """True if a MAT-file's variable names are PyShoe's (``imu`` and ``ts``)."""
    return all(n in mat_names for n in REQUIRED)


def mat_names(path: str, max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> list[str]:
    """The variable names of a MAT-file (no data kept); a :class:`RecordingError` if it is none."""
    with open_binary(path) as f:
        return matv5.read_mat(f, path, max_uncompressed_bytes=max_uncompressed_bytes, only=set()).all_names


def read_pyshoe(path: str, *, warn: bool = True,
                max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a PyShoe processed trial (``.mat``, or ``.mat.gz``) into a :class:`Recording` (see the module doc)."""
    path = str(path)
    with open_binary(path) as f:
        mat = matv5.read_mat(f, path, max_uncompressed_bytes=max_uncompressed_bytes)
    missing = [n for n in REQUIRED if n not in mat]
    if missing:
        raise RecordingError(f"not a PyShoe trial: no MAT-file variable {', '.join(missing)} (it has: "
                             f"{', '.join(mat.names()) or 'none'})", path)

    def numeric(name: str) -> np.ndarray:
        v = mat[name]
        if isinstance(v, str):
            raise RecordingError(f"PyShoe variable {name!r} is text, not numbers", path)
        return np.asarray(v, dtype=np.float64)

    imu, ts = numeric("imu"), numeric("ts").ravel()
    if imu.ndim != 2 or imu.shape[1] != 6:
        raise RecordingError(f"PyShoe 'imu' is {'x'.join(map(str, imu.shape))}, not N x 6 (ax ay az gx gy gz)", path)
    n = len(imu)
    if len(ts) != n:
        raise RecordingError(f"PyShoe 'ts' has {len(ts)} times for {n} 'imu' rows", path)
    if not n:
        raise RecordingError("no sensor events found", path)
    j = first_bad_time(ts)
    if j is not None:
        raise RecordingError(f"PyShoe 'ts' value {j + 1} is not a usable time: {float(ts[j])!r}", path)
    t_ns = np.round(ts * 1e9).astype(np.int64)
    streams = {ACC: make_stream(ACC, t_ns, imu[:, 0:3], note="accelerometer, sensor axes (z down)"),
               GYRO: make_stream(GYRO, t_ns, imu[:, 3:6], note="gyroscope, sensor axes (z down)")}
    if "gt" in mat:
        gt = numeric("gt")
        if gt.ndim != 2 or gt.shape != (n, 3):
            raise RecordingError(f"PyShoe 'gt' is {'x'.join(map(str, gt.shape))}, not {n} x 3 (one VICON position "
                                 "per 'imu' row)", path)
        streams[POSI] = make_stream(POSI, t_ns, np.column_stack([gt[:, 1], gt[:, 0], gt[:, 2]]), POSI_COLUMNS,
                                    "m,m,m", "ground truth: VICON foot position at every sample, local ENU metres "
                                             "(the file's gt as (y, x, z): its horizontal axes are mirrored)")
    labels = [d for d in DETECTORS if f"zv_{d}_opt" in mat]
    if labels:
        cols = []
        for d in labels:
            v = numeric(f"zv_{d}_opt").ravel()
            if len(v) != n:
                raise RecordingError(f"PyShoe 'zv_{d}_opt' has {len(v)} labels for {n} samples", path)
            cols.append(v)
        spec = EXTRA_STREAM_SPECS[ZERO_VELOCITY]
        streams[ZERO_VELOCITY] = make_stream(ZERO_VELOCITY, t_ns, np.column_stack(cols), labels, spec["unit"],
                                             "PyShoe's zero-velocity labels (1 = still), each detector at its "
                                             "per-trial optimal threshold")
    meta: dict = {
        "source_format": FORMAT,
        "app": "PyShoe (processed trial)",
        "time_base": "t_ns = round(ts * 1e9): the file's ts (s); absolute time unknown",
        "mat_header": mat.header[:200],
    }
    thresholds = {d: float(numeric(f"G_{d}_opt").ravel()[0]) for d in DETECTORS
                  if f"G_{d}_opt" in mat and numeric(f"G_{d}_opt").size}
    if thresholds:
        meta["pyshoe_thresholds"] = thresholds
    if "trial_error" in mat:
        meta["pyshoe_errors_m"] = dict(zip(DETECTORS, numeric("trial_error").ravel().tolist()))
    if "best_detector" in mat and "best_error" in mat and numeric("best_error").size:
        best = mat["best_detector"]
        meta["pyshoe_best"] = [str(best if isinstance(best, str) else np.asarray(best).ravel()[0]).strip(),
                               float(numeric("best_error").ravel()[0])]
    if mat.skipped:
        meta["mat_variables_skipped"] = dict(mat.skipped)
    rec = Recording(streams, device={"model": "LORD MicroStrain 3DM-GX3-25", "placement": "foot",
                                     "axes": "sensor axes, z down"},
                    metadata=meta, source=path)
    return finish(rec, warn=warn)
