"""NMEA satellite status for Kubrak et al.'s C/N0 rule (issue #10): parsing, checksums, never raising."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from core.gnss.nmea import NmeaSatelliteStatus


def _cs(body: str) -> str:
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"${body}*{x:02X}"


def _epoch(snrs_gps, used_gps, snrs_gal=(), used_gal=()):
    out = []
    sats = [(p, s) for p, s in snrs_gps]
    for i in range(0, len(sats), 4):
        chunk = sats[i:i + 4]
        body = f"GPGSV,{(len(sats) + 3) // 4},{i // 4 + 1},{len(sats):02d}," + ",".join(
            f"{p:02d},45,120,{s}" for p, s in chunk)
        out.append(_cs(body))
    if snrs_gal:
        out.append(_cs(f"GAGSV,1,1,{len(snrs_gal):02d}," + ",".join(f"{p:02d},30,200,{s}" for p, s in snrs_gal)))
    prns = list(used_gps) + [""] * (12 - len(used_gps))
    out.append(_cs("GNGSA,A,3," + ",".join(str(p) for p in prns) + ",1.8,1.0,1.5,1"))
    if used_gal:
        prns = list(used_gal) + [""] * (12 - len(used_gal))
        out.append(_cs("GNGSA,A,3," + ",".join(str(p) for p in prns) + ",1.8,1.0,1.5,3"))
    out.append(_cs("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"))
    return out


def _run(sentences):
    p = NmeaSatelliteStatus()
    res = [r for r in (p.update(s) for s in sentences) if r is not None]
    return p, res


def test_fourth_strongest_of_the_satellites_used_across_constellations():
    # GPS 5 used (40, 38, 30, 22, 18) + one in view but not used (45); Galileo PRN 5 used at 33 (same PRN as a
    # GPS satellite: the constellations are told apart)
    s = _epoch([(1, 40), (3, 38), (5, 30), (7, 22), (9, 18), (11, 45)], [1, 3, 5, 7, 9], [(5, 33)], [5])
    _, res = _run(s)
    assert res == [(6.0, 30.0)]  # 40, 38, 33, 30 -> the 4th is 30


def test_fewer_than_four_used_gives_nan_and_epochs_do_not_mix():
    s = _epoch([(1, 40), (3, 38), (5, 30)], [1, 3, 5]) + _epoch([(2, 20), (4, 21), (6, 19), (8, 24)], [2, 4, 6, 8])
    _, res = _run(s)
    assert res[0][0] == 3.0 and math.isnan(res[0][1])
    assert res[1] == (4.0, 19.0)


def test_bad_checksums_and_garbage_are_counted_not_used():
    s = _epoch([(1, 40), (3, 38), (5, 30), (7, 22)], [1, 3, 5, 7])
    s[0] = s[0][:-2] + "00"  # the GSV's checksum broken: its SNRs are not used
    p, res = _run(["garbage", "", "$", "$GPXXX"] + s)
    assert p.n_bad >= 4
    assert res[0][0] == 4.0 and math.isnan(res[0][1])


_GOOD = _epoch([(1, 40), (3, 38), (5, 30), (7, 22)], [1, 3, 5, 7])


@settings(max_examples=150, deadline=None)
@given(st.lists(st.one_of(st.text(max_size=80), st.sampled_from(_GOOD),
                          st.sampled_from(_GOOD).map(lambda x: x[: len(x) // 2])), max_size=30))
def test_never_raises_on_anything(sentences):
    p, res = _run(sentences)
    for n, c in res:
        assert (math.isnan(n) or n >= 0) and (math.isnan(c) or 0 <= c <= 99)
