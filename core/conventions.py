"""Constants and edge conversions for the conventions in :mod:`core` (see its docstring)."""

from __future__ import annotations

import math

import numpy as np

#: Standard gravity, m/s^2 (used only as a prior; the pipeline estimates local g).
STANDARD_GRAVITY_M_S2 = 9.80665

#: Stream names of a recording and the meaning of their value columns.
ACC = "acc"  #: accelerometer, m/s^2, gravity included, device frame
GYRO = "gyro"  #: gyroscope, rad/s, device frame
MAG = "mag"  #: magnetometer, uT, device frame (calibrated: hard iron removed by the OS if it can)
GPS = "gps"  #: GNSS fix: lat_deg, lon_deg, alt_m, horizontal accuracy m, speed m/s, course deg (bearing)
PRESSURE = "pressure"  #: barometer, hPa (= mbar, as Android reports it): core.floors
ROTVEC = "rotvec"  #: the phone's own attitude (Android rotation vector) as an ENU quaternion w, x, y, z
#: GNSS receiver status per fix: satellites used in the fix, C/N0 of the 4th strongest of them (dB-Hz, nan if < 4)
GNSS_STATUS = "gnss_status"

NS_PER_S = 1_000_000_000

#: How the phone is carried (issue #17): the names shared by the carry-mode detector
#: (core.pdr.carry), the simulator's placements, the recordings' metadata and the benchmark.
CARRY_HANDHELD = "handheld"  #: in the hand in front of the body: reading, texting (screen roughly up)
CARRY_SWINGING = "swinging"  #: in a hand swinging at the side, with the arm
CARRY_POCKET = "pocket"  #: in a trouser pocket, moving with the thigh
CARRY_BAG = "bag"  #: in a bag, backpack or pouch: loosely coupled to the trunk
CARRY_EAR = "ear"  #: held at the ear (a call): upright beside the head
CARRY_STILL = "still"  #: not walking: on a table, in the hand while standing, in a vehicle
CARRY_MODES = (CARRY_HANDHELD, CARRY_SWINGING, CARRY_POCKET, CARRY_BAG, CARRY_EAR, CARRY_STILL)
#: the carry modes in words, for the summary and the app
CARRY_WORDS = {CARRY_HANDHELD: "in the hand", CARRY_SWINGING: "swinging in the hand", CARRY_POCKET: "in a pocket",
               CARRY_BAG: "in a bag", CARRY_EAR: "at the ear", CARRY_STILL: "not walking"}


def ns_to_s(t_ns) -> float:
    """Nanoseconds to seconds (float)."""
    return t_ns * 1e-9


def wrap_angle(angle_rad):
    """Wrap angles (rad) to [-pi, pi): a float gives a float, an array (or list) an array.

    The project's one angle wrap.
    """
    if isinstance(angle_rad, (float, int)):
        return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
    return (np.asarray(angle_rad, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def bearing_deg(heading_rad: float) -> float:
    """ENU heading (counter-clockwise from East, rad) to compass bearing (clockwise from North, deg, [0, 360))."""
    return (90.0 - math.degrees(heading_rad)) % 360.0


def heading_from_bearing_deg(bearing: float) -> float:
    """Compass bearing (clockwise from North, deg) to ENU heading (counter-clockwise from East, rad, wrapped)."""
    return wrap_angle(math.radians(90.0 - bearing))
