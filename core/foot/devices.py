"""Several IMUs in one recording: how the streams of each device are named.

The primary device (the phone that records) keeps the plain stream names of
:mod:`core.recording` (``acc``, ``gyro``, ``mag``, ...).  Every other device's
streams are named ``<kind>@<device>``, e.g. ``acc@left_foot``,
``gyro@waist``, ``mag@right_foot``: the kind before the ``@`` says what the
values are (same columns, units and axes convention as the plain stream of
that kind), the part after it which device.  Device names are lower-case
words with ``_`` (``waist``, ``left_foot``, ``right_foot``, ``shoe``); the
recording's ``device["placement"]`` says where the primary device was, and
``metadata["devices"]`` may describe the others (``{"left_foot": {"model":
..., "placement": "left foot, instep"}}``).

The file format allows these names as they are (a stream name is any text
without a comma that the header declares); only :func:`core.recording.make_stream`
needs the columns given for a name it does not know, which
:func:`device_stream` does.
"""

from __future__ import annotations

from core.recording import STREAM_SPECS, Recording, Stream, make_stream

SEPARATOR = "@"


def stream_name(kind: str, device: str = "") -> str:
    """``"acc"`` for the primary device, ``"acc@waist"`` for the device ``waist``."""
    if SEPARATOR in kind or "," in kind or "," in device or SEPARATOR in device:
        raise ValueError(f"bad stream kind {kind!r} or device {device!r}")
    return f"{kind}{SEPARATOR}{device}" if device else kind


def split_name(name: str) -> tuple[str, str]:
    """``"acc@waist"`` -> ``("acc", "waist")``; ``"acc"`` -> ``("acc", "")``."""
    kind, _, device = name.partition(SEPARATOR)
    return kind, device


def device_stream(kind: str, device: str, t_ns, values, note: str | None = None) -> Stream:
    """A stream of ``kind`` (one of :data:`core.recording.STREAM_SPECS`) for ``device``."""
    spec = STREAM_SPECS[kind]
    return make_stream(stream_name(kind, device), t_ns, values, columns=spec["columns"], unit=spec["unit"],
                       note=note if note is not None else spec["note"])


def devices(recording: Recording) -> list[str]:
    """The devices that have streams in a recording ("" = primary), primary first."""
    found = {split_name(n)[1] for n in recording.streams if recording.has(n)}
    return sorted(found, key=lambda d: (d != "", d))


def has_imu(recording: Recording, device: str = "") -> bool:
    return recording.has(stream_name("acc", device)) and recording.has(stream_name("gyro", device))
