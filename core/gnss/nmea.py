"""Receiver signal quality from NMEA 0183 sentences: the satellites in a fix and their C/N0.

Kubrak et al. (2006) decide whether a fix can be trusted from the receiver:
"if the C/N0 of the 4th satellite used to compute the position solution is
below 25 dB-Hz, the integrated system deliberately relies exclusively on the
IMU data".  A phone gives this through Android's ``GnssStatus`` (per
satellite ``getCn0DbHz`` and ``usedInFix``) or, in every receiver, through
the NMEA stream (``LocationManager.addNmeaListener``), which a Python app can
listen to (``OnNmeaMessageListener`` is an interface; ``GnssStatus.Callback``
is an abstract class, which pyjnius cannot implement).

:class:`NmeaSatelliteStatus` reads the sentences one at a time:

* ``GSV`` (satellites in view, talker per constellation: GP GPS, GL GLONASS,
  GA Galileo, GB/BD BeiDou, GQ QZSS, GI NavIC): PRN and SNR (dB-Hz, the C/N0
  NMEA reports) of each satellite;
* ``GSA`` (DOP and active satellites): the PRNs used in the fix, per
  constellation (the talker, or with the ``GN`` talker the NMEA 4.10 system
  ID field);
* ``GGA`` or ``RMC`` closes an epoch: :meth:`NmeaSatelliteStatus.update`
  returns ``(n_used, cn0_4th_dbhz)`` -- the values of the ``gnss_status``
  stream (:data:`core.conventions.GNSS_STATUS`) -- and starts the next epoch.
  Most receivers send both: only a closer after new GSV/GSA sentences closes
  one (the other would report an empty epoch, 0 satellites, and the C/N0
  rule would reject every fix: issue #26).  Without a GSA in the epoch the
  satellites in use are unknown (nan), not 0.

Sentences with a bad checksum, unknown talkers or garbage are counted in
:attr:`NmeaSatelliteStatus.n_bad` and otherwise ignored: the parser never
raises on what a receiver sends.
"""

from __future__ import annotations

import math

#: talker ID -> constellation (NMEA 4.10 system IDs: 1 GPS, 2 GLONASS, 3 Galileo, 4 BeiDou, 5 QZSS, 6 NavIC)
TALKERS = {"GP": 1, "GL": 2, "GA": 3, "GB": 4, "BD": 4, "GQ": 5, "GI": 6}


def _checksum_ok(sentence: str) -> tuple[bool, str]:
    """(valid, body without '$' and checksum); a sentence without a checksum is taken as it is."""
    s = sentence.strip()
    if not s.startswith(("$", "!")):
        return False, ""
    body, star, cs = s[1:].partition("*")
    if not star:
        return True, body
    x = 0
    for ch in body:
        x ^= ord(ch)
    try:
        return int(cs[:2], 16) == x, body
    except ValueError:
        return False, body


def _int(v: str) -> int | None:
    try:
        return int(v)
    except ValueError:
        return None


class NmeaSatelliteStatus:
    """The satellites used in each fix and the C/N0 of the 4th strongest, from NMEA sentences."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self._snr: dict[tuple[int, int], float] = {}  # (system, prn) -> SNR dB-Hz, this epoch
        self._used: set[tuple[int, int]] = set()
        self._fresh = False  # a GSV or GSA since the last closed epoch
        self._gsa_seen = False
        self.n_bad = 0
        self.n_epochs = 0
        self.last: tuple[float, float] | None = None

    def update(self, sentence: str) -> tuple[float, float] | None:
        """One sentence; returns ``(n_used, cn0_4th_dbhz)`` when it closes an epoch (GGA/RMC), else None."""
        if not isinstance(sentence, str):
            self.n_bad += 1
            return None
        ok, body = _checksum_ok(sentence)
        fields = body.split(",")
        if not ok or len(fields[0]) < 5:
            self.n_bad += 1
            return None
        talker, kind = fields[0][:2], fields[0][2:5]
        if kind == "GSV":
            self._gsv(TALKERS.get(talker), fields)
        elif kind == "GSA":
            self._gsa(talker, fields)
        elif kind in ("GGA", "RMC") and self._fresh:
            return self._close()
        return None

    def _gsv(self, system: int | None, f: list) -> None:
        if system is None:
            self.n_bad += 1
            return
        self._fresh = True
        # $xxGSV,total,msg,in_view,[prn,elev,azim,snr]x1..4[,signal_id]
        for k in range(4, len(f) - 3, 4):
            prn, snr = _int(f[k]), f[k + 3]
            if prn is None:
                continue
            try:
                v = float(snr) if snr else math.nan
            except ValueError:
                v = math.nan
            if math.isfinite(v) and 0.0 <= v <= 99.0:
                key = (system, prn)
                self._snr[key] = max(v, self._snr.get(key, -1.0))  # one satellite on several signals: the strongest

    def _gsa(self, talker: str, f: list) -> None:
        # $xxGSA,mode,fix,prn x12,pdop,hdop,vdop[,system_id]
        system = TALKERS.get(talker)
        if talker == "GN" and len(f) >= 19:
            system = _int(f[18])
        if system is None:
            self.n_bad += 1
            return
        self._fresh = self._gsa_seen = True
        for v in f[3:15]:
            prn = _int(v)
            if prn is not None and prn > 0:
                self._used.add((system, prn))

    def _close(self) -> tuple[float, float]:
        snrs = sorted((self._snr[k] for k in self._used if k in self._snr), reverse=True)
        n_used = float(len(self._used)) if self._gsa_seen else math.nan
        out = (n_used, snrs[3] if len(snrs) >= 4 else math.nan)
        self._snr.clear()
        self._used.clear()
        self._fresh = self._gsa_seen = False
        self.n_epochs += 1
        self.last = out
        return out
