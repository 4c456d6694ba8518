"""Tuning and report splits of the foot-mounted benchmark (issue #11, "Honest numbers").

Declared before any foot-mounted parameter was chosen.  Every recording
belongs to exactly one split:

``tuning``
    Thresholds and noise settings of :mod:`core.foot` may be chosen by looking
    at these numbers.
``report``
    The numbers we publish and check the targets on; nothing is tuned on them.

PyShoe VICON (``pyshoe_vicon``)
    The trial files sorted by name and numbered from 1: odd numbers (1st,
    3rd, ...) are **tuning**, even numbers **report**.
    *Walking trials* (for the stance-detection F1 target) are the trials not
    excluded as non-bipedal by the LLIO authors (listed in the dataset's
    README) and not from the 2017-11-27 session, whose mean |acc| of 16-18
    m/s^2 the README reads as running.  The rule uses no result of ours.
IPOL healthy gait, both feet (``ipol_healthy_gait_xsens``)
    By subject: odd subject numbers are **tuning**, even numbers **report**
    (all trials of a subject in one split).  This is a different declaration
    from ``benchmarks/splits.py`` (where the whole set is tuning because the
    hand-held stride model was fitted on the lower-back sensor); nothing of
    the foot-mounted chain was fitted on it.
x-io foot IMU (``xio_foot_imu``)
    All **report**: nothing is tuned on it.
"""

from __future__ import annotations

TUNING = "tuning"
REPORT = "report"
SPLITS = (TUNING, REPORT)

#: trials the LLIO authors left out as non-bipedal (README of the PyShoe copy), those in our copy
PYSHOE_NON_BIPEDAL = (
    "2017-11-22-11-28-03", "2017-11-22-11-37-47",
    "2017-11-27-11-12-44", "2017-11-27-11-18-11", "2017-11-27-11-19-16", "2017-11-27-11-22-22",
    "2018-02-09-11-16-53", "2018-02-09-11-18-04", "2018-02-09-11-19-39", "2018-02-09-11-22-01",
)
#: sessions whose trials the README reads as running (mean |acc| 16-24 m/s^2)
PYSHOE_RUNNING_SESSIONS = ("2017-11-27", "2017-12-15")


def pyshoe_split(position: int) -> str:
    """PyShoe trial at 1-based ``position`` in the name-sorted list: odd = tuning, even = report."""
    if int(position) < 1:
        raise ValueError(f"positions start at 1, got {position}")
    return TUNING if int(position) % 2 == 1 else REPORT


def pyshoe_is_walking(name: str) -> bool:
    """Whether a PyShoe trial counts as walking for the stance F1 target (see the module docstring)."""
    if name in PYSHOE_NON_BIPEDAL or any(name.startswith(s) for s in PYSHOE_RUNNING_SESSIONS):
        return False
    return name.startswith("20")


def ipol_split(subject: int) -> str:
    """IPOL subject number: odd = tuning, even = report."""
    return TUNING if int(subject) % 2 == 1 else REPORT


def xio_split(name: str) -> str:
    return REPORT


def check_split(split: str) -> str:
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}: one of {', '.join(SPLITS)}")
    return split
