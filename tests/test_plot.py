"""``--plot`` says what it shows (issue #29): every "not used" GPS fix under its verdict, the hidden window of
``--gps-outage`` shaded and named, a map-matched track zoomed with the floor around it."""

from __future__ import annotations

import numpy as np
import pytest

from core.pdr.pipeline import Track
from desktop.plot import plot_track, verdict_group


def test_verdicts_group_the_fusions_reasons_by_their_rule():
    assert verdict_group("accuracy 35 m > 20 m") == verdict_group("accuracy 48 m > 20 m") == \
        "reported accuracy worse than 20 m"
    assert verdict_group("innovation gate: NIS 23.1 > 9.2") == verdict_group("innovation gate: NIS 99.0 > 9.2")
    assert verdict_group("hidden (outage)") == "hidden by --gps-outage"
    assert verdict_group("GPS judged unusable: reported accuracy too coarse; fixes inconsistent with the steps") \
        == "judged unusable: reported accuracy too coarse"
    assert verdict_group("something new") == "something new"  # an unknown reason is shown as it is


@pytest.fixture
def drawn(monkeypatch):
    """The figure plot_track made, kept open for the test."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    close = plt.close
    figs = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figs.append(fig))
    yield figs
    for f in figs:
        close(f)


def _track(n=40):
    t = (np.arange(1, n + 1) * 500_000_000).astype(np.int64)
    h = np.zeros(n)
    e = np.cumsum(np.full(n, 0.7))
    return Track(t, np.full(n, 0.7), h, e, np.zeros(n))


def test_legend_names_each_verdict_and_the_hidden_window(tmp_path, drawn):
    tr = _track()
    fixes = ([1.0, 2.0, 3.0, 4.0], [0.5, 0.5, 0.5, 0.5], [True, False, False, False],
             ["", "accuracy 35 m > 20 m", "accuracy 40 m > 20 m", "innovation gate: NIS 30.0 > 9.2"])
    plot_track(str(tmp_path / "p.png"), tr, fixes=fixes,
               hidden=[(int(tr.t_ns[10]), int(tr.t_ns[20]), "GPS hidden 5-10 s (--gps-outage 5:5)")])
    ax = drawn[0].axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "GPS not used, reported accuracy worse than 20 m (2)" in labels
    assert "GPS not used, outside the filter's innovation gate (NIS) (1)" in labels
    assert "GPS hidden 5-10 s (--gps-outage 5:5)" in labels
    assert any(t.get_text().startswith("GPS hidden 5-10 s") for t in ax.texts)  # named on the plot too
    assert (tmp_path / "p.png").stat().st_size > 0


def test_a_map_matched_track_is_zoomed_with_the_floor_as_context(tmp_path, drawn):
    tr = _track()  # 28 m East from (0, 0)
    walls = np.array([[-120.0, -120.0, 120.0, -120.0], [-120.0, 120.0, 120.0, 120.0], [10.0, -3.0, 10.0, -1.0]])
    plot_track(str(tmp_path / "m.png"), tr, walls=walls)
    ax = drawn[0].axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 <= 0.0 and x1 >= 28.0 and x1 - x0 < 60.0  # the walk, not the 240 m floor
    assert y0 > -120.0 and y1 < 120.0
