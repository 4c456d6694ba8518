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


#: a GPS fix's "not used" reason (:class:`core.gnss.base.FixRecord`) -> the verdict the legend names: the
#: fusion's reasons carry the fix's own numbers, the legend groups them by the rule that turned them away
_VERDICT_GROUPS = (
    (r"^accuracy [\d.]+ m > ([\d.]+ m)", r"reported accuracy worse than \1"),
    (r"^speed .* is not walking", "speed is not walking"),
    (r"^(innovation|course|velocity) gate", r"outside the filter's \1 gate (NIS)"),
    (r"^C/N0 .*< ([\d.]+)", r"weak signal: 4th satellite's C/N0 < \1 dB-Hz"),
    (r"^[\d.]+ satellites in use", "fewer than 4 satellites"),
    (r"^waiting for a first fix within ([\d.]+ m)", r"before the first fix within \1"),
    (r"^hidden \(outage\)", "hidden by --gps-outage"),
    (r"^GPS judged (\w+): ([^;]*)", r"judged \1: \2"),  # the first cause names the group
    (r"^GPS unreliable: the velocity model", "unreliable: velocity-model coefficients jumped"),
)


def verdict_group(reason: str) -> str:
    """The legend's name for a fix's reason of not being used (its numbers dropped, the rule kept)."""
    import re

    for pat, rep_ in _VERDICT_GROUPS:
        m = re.match(pat, reason or "")
        if m:
            return m.expand(rep_)
    return (reason or "not used").strip()


def view_limits(points, margin_frac: float = 0.25, min_margin_m: float = 8.0):
    """``((x0, x1), (y0, y1))`` around ``points`` (n, 2) with a margin: the view of a track on a big floor."""
    p = np.asarray(points, float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if not len(p):
        return None
    lo, hi = p.min(axis=0), p.max(axis=0)
    m = max(min_margin_m, margin_frac * float(np.max(hi - lo)))
    return (lo[0] - m, hi[0] + m), (lo[1] - m, hi[1] + m)


def plot_track(path: str, track, *, title: str = "PDR track", truth_en=None, landmarks_en=None,
               others: dict | None = None, subtitle: str = "", fixes=None, landmarks_label: str = "landmarks",
               reference=None, walls=None, start_en=(0.0, 0.0), track_label: str = "PDR", hidden=None,
               track_unit: str = "steps") -> None:
    """Write a PNG of the track (East/North metres, equal axes) with start and end marked.

    ``walls``: optional (k, 4) wall segments ``x0, y0, x1, y1`` of a floor plan, drawn under everything;
    ``start_en``: where the track starts (the origin, or a map-matched track's start in plan metres).
    ``truth_en``: optional (n, 2) reference path; ``landmarks_en``: optional (k, 2)
    points; ``others``: optional ``{label: (east array, north array)}`` of other tracks;
    ``fixes``: optional ``(east, north, accepted[, reasons])`` GPS fixes (used ones filled, the others hollow,
    one colour and legend entry per verdict, :func:`verdict_group`, when the reasons are given);
    ``hidden``: optional ``[(t0_ns, t1_ns, label)]`` time windows whose GPS was hidden (``--gps-outage``): the
    track walked in each is shaded and the window named on the plot;
    with ``walls`` the view is the track's (and the truth's) surroundings, the floor around it as context.
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
        if len(lm) > 200:  # a reference trajectory (PyShoe's VICON at 200 Hz), not surveyed points: a line
            ax.plot(lm[:, 0], lm[:, 1], "-", color="tab:green", lw=1.2, alpha=0.8,
                    label=f"true path ({len(lm)} reference positions)")
        else:
            ax.plot(lm[:, 0], lm[:, 1], "--", color="tab:green", lw=0.8, alpha=0.6)
            ax.plot(lm[:, 0], lm[:, 1], "s", color="tab:green", ms=6, label=landmarks_label)
        if len(lm) <= 40:  # numbered; landmarks at one place (a loop's start and end) share one label
            span = float(np.max(np.ptp(lm[:, :2], axis=0))) if len(lm) > 1 else 0.0
            for x, y, text in label_groups(lm, radius_m=max(0.5, 0.04 * span)):  # no two labels overlap
                ax.annotate(text, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=6,
                            color="tab:green")
    if reference is not None:
        label, re_, rn = reference
        ax.plot(np.asarray(re_, float), np.asarray(rn, float), ".", color="0.45", ms=3, label=label)
    if fixes is not None and len(fixes[0]):
        fe, fn, ok = (np.asarray(v) for v in fixes[:3])
        ok = ok.astype(bool)
        ax.plot(fe[ok], fn[ok], ".", color="tab:orange", ms=3, alpha=0.6, label=f"GPS fixes used ({int(ok.sum())})")
        if (~ok).any():
            reasons = list(fixes[3]) if len(fixes) > 3 else ["not used"] * len(ok)
            groups: dict = {}
            for i in np.flatnonzero(~ok):
                groups.setdefault(verdict_group(reasons[i]), []).append(i)
            colours = ("tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "0.3")
            for k, (name, idx) in enumerate(sorted(groups.items(), key=lambda kv: -len(kv[1]))):
                ax.plot(fe[idx], fn[idx], "o", mfc="none", color=colours[k % len(colours)], ms=4, alpha=0.6,
                        label=f"GPS not used, {name} ({len(idx)})")
    for label, (oe, on) in (others or {}).items():
        ax.plot(oe, on, "-", lw=1, alpha=0.8, label=label)
    t_steps = np.asarray(track.t_ns, dtype=np.int64)
    for k, (h0, h1, hlabel) in enumerate(hidden or ()):
        inside = np.flatnonzero((t_steps >= h0) & (t_steps <= h1))
        if len(inside):
            seg = np.concatenate([[max(inside[0], 0)], inside + 1])  # the step before, then the steps inside
            ax.plot(e[seg], n[seg], "-", color="gold", lw=9, alpha=0.45, solid_capstyle="round", zorder=1,
                    label=hlabel)
            mid = seg[len(seg) // 2]
            ax.annotate(hlabel, (e[mid], n[mid]), textcoords="offset points", xytext=(8, -12), fontsize=7,
                        color="darkgoldenrod", bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "gold",
                                                     "alpha": 0.8})
    ax.plot(e, n, "-", color="tab:blue", lw=1.6, label=f"{track_label} ({len(track)} {track_unit})")
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
    if walls is not None and len(walls):  # zoom to the walk: the floor plan stays around it as context
        pts = [np.column_stack([e, n])]
        if landmarks_en is not None:
            pts.append(np.asarray(landmarks_en, float)[:, :2])
        if truth_en is not None:
            pts.append(np.asarray(truth_en, float)[:, :2])
        lim = view_limits(np.concatenate(pts))
        if lim is not None:
            (x0, x1), (y0, y1) = lim
            cx, cy, half = (x0 + x1) / 2, (y0 + y1) / 2, max(x1 - x0, y1 - y0) / 2
            ax.set_xlim(cx - half, cx + half)
            ax.set_ylim(cy - half, cy + half)
            ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    import textwrap

    ax.set_title("\n".join(textwrap.fill(t, 95) for t in (title, subtitle) if t), fontsize=9)
    ax.grid(True, alpha=0.3)
    handles = ax.get_legend_handles_labels()[0]
    if len(handles) > 7:  # a long legend goes under the plot, where it hides nothing
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2, fontsize=7, frameon=False)
        fig.set_size_inches(7.5, 7 + 0.17 * ((len(handles) + 1) // 2))
    else:
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")  # the legend under the axes is part of the picture
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

