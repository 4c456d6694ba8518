"""The common shape of a benchmark trial, shared by every dataset reader.

A dataset module exposes::

    NAME: str                                  # folder name under the data root, e.g. "ipin2023_track3"
    def available(root: Path) -> bool          # is the dataset present under root?
    def trials(root: Path) -> list[Trial]      # cheap: recordings are loaded lazily

Harnesses load a trial with ``trial.open()`` (``load()`` plus the ground truth
that needs the recording, see ``Trial.resolve``).

Every trial's recording follows the conventions of :mod:`core` (converted at
the edge by the reader or by ``core.importers``), and every ground-truth time
is on the recording's own clock (``t_ns``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from core.recording import Recording


def default_data_root() -> Path:
    """``../shared/data`` beside the repository checkout."""
    return Path(__file__).resolve().parents[2].parent / "shared" / "data"


@dataclass
class Landmarks:
    """Surveyed positions the walker passed, on the recording clock, in a local ENU frame (m)."""

    t_ns: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    #: geodetic origin of the ENU frame (lat_deg, lon_deg) when the landmarks came from lat/lon
    origin_lat_lon: tuple[float, float] | None = None


@dataclass
class ReferenceTrack:
    """A dense reference track (e.g. the recording's own GNSS fixes) on the recording clock, local ENU metres.

    It is truth for the metrics only: readers remove its stream from the
    recording before any estimator sees it.
    """

    t_ns: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    #: geodetic origin (lat_deg, lon_deg) of the ENU frame: the first fix
    origin_lat_lon: tuple[float, float]
    #: horizontal accuracy of each fix (m, nan when unknown)
    hacc_m: np.ndarray | None = None
    #: where it comes from, e.g. "GPS (Sensor Logger Location.csv)"
    source: str = ""


@dataclass(frozen=True)
class Site:
    """Where and when a dataset was recorded: what a live app knows from a coarse location fix and its clock."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    #: a ``datetime.date`` / ``datetime.datetime`` (UTC) of the recording
    when: object

    def magnetic_field(self) -> tuple[float, float, float]:
        """World Magnetic Model at the site: ``(declination_rad, inclination_rad, total_uT)`` (:mod:`core.geodesy`)."""
        from core.geodesy import magnetic_field

        return magnetic_field(self.lat_deg, self.lon_deg, self.alt_m, self.when)


@dataclass
class Trial:
    dataset: str
    name: str
    #: loads the recording (lazily: some are large)
    load: Callable[[], Recording]
    #: where the sensor was carried: "hand", "pocket", "waist", "foot", ...
    placement: str = "hand"
    #: ground-truth step instants (t_ns on the recording clock), if known
    step_t_ns: np.ndarray | None = None
    #: ground-truth step count, if known
    step_count: int | None = None
    #: ground-truth walked distance (m), if known
    distance_m: float | None = None
    landmarks: Landmarks | None = None
    #: subject facts: height_m, weight_kg, age, sex, id ... (what the dataset gives)
    subject: dict = field(default_factory=dict)
    #: time window (t_ns) of the walk proper, if the dataset marks it
    walk_t_ns: tuple[int, int] | None = None
    #: other counters' step counts for comparison (name -> count)
    peer_step_counts: dict = field(default_factory=dict)
    notes: str = ""
    #: magnetic declination at the site (rad, east positive) when the landmarks are in a
    #: true-north frame: a magnetic heading h becomes h - declination_rad there.  Our pipeline is
    #: given it (``benchmarks.run.make_pipeline``); the peers' headings are corrected by it afterwards
    declination_rad: float | None = None
    #: where and when the recording was made (the World Magnetic Model there), if known
    site: Site | None = None
    #: a dense reference track (GNSS) for the metrics, if the dataset has one
    reference_track: ReferenceTrack | None = None
    #: free facts for the report (phone, route, surface, ...), name -> short value
    info: dict = field(default_factory=dict)
    #: ground truth that can only be read with the recording (e.g. landmarks whose clock the
    #: importer maps): called by :meth:`open`, returns the Trial fields to set (dict fields are updated)
    resolve: Callable[[Recording], dict] | None = None

    def open(self) -> Recording:
        """Load the recording and fill in the ground truth that depends on it (see ``resolve``)."""
        rec = self.load()
        if self.resolve is not None:
            for name, value in self.resolve(rec).items():
                old = getattr(self, name, None)
                if isinstance(old, dict) and isinstance(value, dict):
                    old.update(value)
                else:
                    setattr(self, name, value)
        return rec
