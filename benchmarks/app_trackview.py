"""The app's track view on long walks: the UI cost of one step at 1 000 ... 50 000 track points (issue #14).

For each track length N (a seeded random walk of 0.7 m steps) the view is built and drawn, then the walk
goes on for ``--steps`` steps with *Follow* on, as in the app: each step appends a point to the session's
lists, calls ``TrackView.set_track`` and redraws.  Two times per step are reported (medians):

update
    ``set_track`` + ``_redraw`` on the Kivy thread (Python);
frame
    the rendered frame after it (``EventLoop.idle``): Kivy tessellates the changed ``Line`` instructions
    there, and Mesa's software renderer (llvmpipe) rasterises everything, which grows with the vertices
    drawn (a phone's GPU does that part in hardware);
static_frame
    a frame with nothing changed: the rasterisation alone;
step
    update + frame - static frame: what a step costs the UI thread beyond drawing the picture, the cost
    issue #14 is about (it must not grow with the track).

``--baseline REV`` also times the view as it was at git revision ``REV`` (``app/track_view.py`` read with
``git show``; before issue #14 every step projected the whole track to pixels and re-tessellated one thick
``Line``), the same way.  The density is set like a phone's (``--density 2.75``, a
5.5 px line).  Not a test: times depend on the machine.

    python -m benchmarks.app_trackview [--steps 40] [--sizes 1000,5000,20000,50000] [--baseline 67c9f5e] [--json F]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.app_trackview", description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="1000,5000,20000,50000")
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--density", default="2.75")
    p.add_argument("--size", default="540x960", help="window WxH (px)")
    p.add_argument("--baseline", default=None, metavar="REV", help="also time app/track_view.py as of git REV")
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    os.environ.setdefault("KIVY_METRICS_DENSITY", a.density)
    from app import kivy_env  # noqa: PLC0415

    kivy_env.prepare(headless=True)
    from kivy.config import Config  # noqa: PLC0415

    w, h = (int(v) for v in a.size.split("x"))
    Config.set("graphics", "width", str(w))
    Config.set("graphics", "height", str(h))
    import numpy as np  # noqa: PLC0415
    from kivy.base import EventLoop  # noqa: PLC0415
    from kivy.core.window import Window  # noqa: PLC0415

    from app.track_view import TrackView  # noqa: PLC0415

    views = [("", TrackView)]
    if a.baseline:
        views.append(("baseline_", _view_at(a.baseline)))

    EventLoop.ensure_window()
    rng = np.random.default_rng(14)

    def walk(n):
        heading = np.cumsum(rng.normal(0.0, 0.15, n - 1))
        return ([0.0] + np.cumsum(0.7 * np.cos(heading)).tolist(),
                [0.0] + np.cumsum(0.7 * np.sin(heading)).tolist())

    def frame():
        Window.canvas.ask_update()
        EventLoop.idle()

    def static_frames(k=15):
        out = []
        for _ in range(k):
            t0 = time.perf_counter()
            frame()
            out.append(time.perf_counter() - t0)
        return 1e3 * statistics.median(out)

    rows = []
    for n in (int(v) for v in a.sizes.split(",")):
        row = {"points": n}
        for prefix, View in views:
            east, north = walk(n)
            tv = View(size=Window.size, pos=(0, 0), size_hint=(None, None))
            Window.add_widget(tv)
            tv.set_track(east, north)
            tv._redraw()
            frame()
            upd, frm = [], []
            for _ in range(a.steps):
                east.append(east[-1] + 0.7)
                north.append(north[-1] + 0.1)
                t0 = time.perf_counter()
                tv.set_track(east, north)
                tv._redraw()
                t1 = time.perf_counter()
                frame()
                t2 = time.perf_counter()
                upd.append(t1 - t0)
                frm.append(t2 - t1)
            r = {"update_ms": 1e3 * statistics.median(upd), "frame_ms": 1e3 * statistics.median(frm),
                 "static_frame_ms": static_frames()}
            r["step_ms"] = r["update_ms"] + r["frame_ms"] - r["static_frame_ms"]
            row.update({prefix + k: v for k, v in r.items()})
            Window.remove_widget(tv)
        rows.append(row)
        print("  ".join(f"{k} {v:7.1f}" if isinstance(v, float) else f"{k} {v:6d}" for k, v in row.items()),
              flush=True)
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump({"density": a.density, "window": a.size, "steps": a.steps, "rows": rows}, f, indent=1)
    return 0


def _view_at(rev: str):
    """``TrackView`` of ``app/track_view.py`` as of git revision ``rev`` (the same kv-free widget)."""
    import importlib.util  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    code = subprocess.run(["git", "show", f"{rev}:app/track_view.py"], cwd=root, capture_output=True, text=True,
                          check=True).stdout
    path = os.path.join(tempfile.mkdtemp(prefix="trackview-"), f"track_view_{rev}.py")
    with open(path, "w", encoding="utf-8") as f:
        f.write(code)
    spec = importlib.util.spec_from_file_location(f"track_view_at_{rev}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.TrackView


if __name__ == "__main__":
    sys.exit(main())
