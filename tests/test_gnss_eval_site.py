"""The GPS benchmark's simulated walks run the outdoor attitude filter (issue #26).

A live app gives the attitude filter the site at its first GPS fix (``Pipeline(site_from_gps=True)``), and
outdoors the filter then drops the field's heading-offset state, which is for a building's bent field.
``benchmarks.gnss_eval`` gave the real walks their site but not the simulated ones: the simulated 5-minute
outages ran with the indoor state (tuning seeds 0-19: 1.90 -> 2.12 % when the state was turned on).
"""

from __future__ import annotations

import math

import pytest

from core.geodesy import magnetic_field, unix_ns_to_datetime
from core.pdr.pipeline import Pipeline
from desktop.simulator import outdoor_site, outdoor_walk, simulate_walk


def test_outdoor_site_is_where_the_walk_got_its_field():
    """Round trip: the WMM field at the site and date given is the field the simulator put there."""
    rec = outdoor_walk(3, minutes=0.3, year=2026.25).recording
    lat, lon, alt, unix_ns = outdoor_site(rec)
    assert (lat, lon) == tuple(rec.metadata["origin_lat_lon"])
    dec, _inc, _total = magnetic_field(lat, lon, alt, unix_ns_to_datetime(unix_ns))
    assert math.degrees(dec) == pytest.approx(rec.metadata["outdoor_walk"]["declination_deg"], abs=1e-6)
    with pytest.raises(ValueError, match="outdoor_walk"):
        outdoor_site(simulate_walk([(0.0, 0.0), (5.0, 0.0)], seed=1).recording)


def test_gnss_eval_gives_the_simulated_walk_its_site(monkeypatch):
    """The pipeline of gnss_eval's simulated walks runs without the heading-offset state and with the site's
    declination (fails before the fix: offset SD 0.1 rad, declination 0)."""
    import benchmarks.gnss_eval as ge

    seen = []
    run = Pipeline.run

    def spy(self, rec, *a, **kw):
        seen.append((self.attitude.settings.mag_offset_sd_rad, self.attitude.declination_rad,
                     rec.metadata["outdoor_walk"]["declination_deg"]))
        return run(self, rec, *a, **kw)

    monkeypatch.setattr(Pipeline, "run", spy)
    monkeypatch.setattr(ge, "VARIANTS", {"pdr": ge.VARIANTS["pdr"]})
    ge.sim_walks([1], minutes=0.25, start_s=5.0, length_s=5.0)
    assert len(seen) == 1
    offset_sd, decl, want_deg = seen[0]
    assert offset_sd == 0.0
    assert math.degrees(decl) == pytest.approx(want_deg, abs=1e-6)
