"""Track plots for the desktop (matplotlib is a desktop extra, imported only here, only when called)."""

from __future__ import annotations

import math

import numpy as np


def label_groups(points, radius_m: float = 0.5) -> list:
    """Number labels for ``points`` (n, 2) in metres, one per place: points within ``radius_m`` of an earlier
    labelled point join its label ("0,13" where a loop starts and ends), so that no two labels overlap there."""
    groups: list = []
    for k, (x, y) in enumerate(np.asarray(points, float)[:, :2]):
        g = next((g for g in groups if math.hypot(x - g[0], y - g[1]) < radius_m), None)
        if g is None:
            groups.append([float(x), float(y), [str(k)]])
        else:
            g[2].append(str(k))
    return [(x, y, ",".join(ks)) for x, y, ks in groups]


def plot_track(path: str, track, *, title: str = "PDR track", truth_en=None, landmarks_en=None,
               others: dict | None = None, subtitle: str = "", fixes=None, landmarks_label: str = "landmarks",
               reference=None, walls=None, start_en=(0.0, 0.0), track_label: str = "PDR") -> None:
    """Write a PNG of the track (East/North metres, equal axes) with start and end marked.

    ``walls``: optional (k, 4) wall segments ``x0, y0, x1, y1`` of a floor plan, drawn under everything;
    ``start_en``: where the track starts (the origin, or a map-matched track's start in plan metres).
    ``truth_en``: optional (n, 2) reference path; ``landmarks_en``: optional (k, 2)
    points; ``others``: optional ``{label: (east array, north array)}`` of other tracks;
    ``fixes``: optional ``(east, north, accepted)`` GPS fixes (used ones filled, rejected ones hollow);
    ``reference``: optional ``(label, east, north)`` reference positions (e.g. good GPS fixes as truth).
    Landmarks are numbered and joined, in the order walked, by a thin dashed line (the true path between them).
    """
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("plots need matplotlib: pip install matplotlib (or the 'desktop' extra)") from e

    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    if walls is not None and len(walls):
        from matplotlib.collections import LineCollection

        w = np.asarray(walls, float).reshape(-1, 2, 2)
        ax.add_collection(LineCollection(w, colors="0.55", linewidths=0.5, zorder=0, label="walls (floor plan)"))
    e = np.concatenate([[float(start_en[0])], np.asarray(track.east_m, float)])
    n = np.concatenate([[float(start_en[1])], np.asarray(track.north_m, float)])
    if truth_en is not None:
        t = np.asarray(truth_en, float)
        ax.plot(t[:, 0], t[:, 1], "-", color="0.6", lw=3, alpha=0.6, label="true path")
    if landmarks_en is not None:
        lm = np.asarray(landmarks_en, float)
        ax.plot(lm[:, 0], lm[:, 1], "--", color="tab:green", lw=0.8, alpha=0.6)
        ax.plot(lm[:, 0], lm[:, 1], "s", color="tab:green", ms=6, label=landmarks_label)
        if len(lm) <= 40:  # numbered; landmarks at one place (a loop's start and end) share one label
            for x, y, text in label_groups(lm):
                ax.annotate(text, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=6,
                            color="tab:green")
    if reference is not None:
        label, re_, rn = reference
        ax.plot(np.asarray(re_, float), np.asarray(rn, float), ".", color="0.45", ms=3, label=label)
    if fixes is not None and len(fixes[0]):
        fe, fn, ok = (np.asarray(v) for v in fixes)
        ok = ok.astype(bool)
        ax.plot(fe[ok], fn[ok], ".", color="tab:orange", ms=3, alpha=0.6, label=f"GPS fixes used ({int(ok.sum())})")
        if (~ok).any():
            ax.plot(fe[~ok], fn[~ok], "o", mfc="none", color="tab:red", ms=4, alpha=0.6,
                    label=f"GPS fixes not used ({int((~ok).sum())})")
    for label, (oe, on) in (others or {}).items():
        ax.plot(oe, on, "-", lw=1, alpha=0.8, label=label)
    ax.plot(e, n, "-", color="tab:blue", lw=1.6, label=f"{track_label} ({len(track)} steps)")
    ax.plot(e[1:], n[1:], ".", color="tab:blue", ms=2)
    ax.plot(e[0], n[0], "o", color="tab:green", ms=9, label="start")
    ax.plot(e[-1], n[-1], "X", color="tab:red", ms=9, label="end")
    if len(track):
        # heading arrow at the end
        h = float(track.heading_rad[-1])
        span = max(np.ptp(e), np.ptp(n), 1.0)
        ax.annotate("", xy=(e[-1] + 0.06 * span * math.cos(h), n[-1] + 0.06 * span * math.sin(h)),
                    xytext=(e[-1], n[-1]), arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 1.5})
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_title(title + (f"\n{subtitle}" if subtitle else ""), fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_distance(path: str, track, *, title: str = "Steps", subtitle: str = "") -> None:
    """Write a PNG of the distance walked over time, one marker per step: for a recording that measures
    steps but not their direction (an accelerometer alone), where a track shape would be made up."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("plots need matplotlib: pip install matplotlib (or the 'desktop' extra)") from e
    t = (np.asarray(track.t_ns, dtype=np.int64) - (int(track.t_ns[0]) if len(track) else 0)) * 1e-9
    d = np.cumsum(np.asarray(track.length_m, float))
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    ax.plot(t, d, ".-", ms=3, lw=1, color="tab:blue", label=f"{len(track)} steps")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance walked (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    import textwrap

    ax.set_title(textwrap.fill(title + (f"\n{subtitle}" if subtitle else ""), 70) +
                 "\nno gyroscope, no magnetometer: no direction, so no track shape", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

