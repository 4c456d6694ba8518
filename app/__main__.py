"""Desktop command: replay a recording in the app.

    python -m app RECORDING [--speed 1|10|max] [--out DIR]
    python -m app RECORDING --speed max --headless --exit-at-end --screenshot shot.png --report report.json
"""

from __future__ import annotations

import argparse
import os
import sys

from app import kivy_env

SPEED_ALIASES = {"1": "1x", "1x": "1x", "10": "10x", "10x": "10x", "max": "max", "inf": "max", "0": "max"}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m app", description="PDR Tracker: replay a recording (desktop) "
                                "or track live (Android).")
    p.add_argument("recording", nargs="?", help="recording to replay (any format core can read)")
    p.add_argument("--speed", default=None, help="replay speed: 1, 10 or max (default: the saved setting, 10)")
    p.add_argument("--out", default=None, help="directory for recordings and exports")
    p.add_argument("--data-dir", default=None, help="directory for the settings (default: Kivy's user data dir)")
    p.add_argument("--size", default=None, help="window size WxH in pixels, e.g. 540x960")
    p.add_argument("--headless", action="store_true", help="render off-screen (no display needed)")
    p.add_argument("--exit-at-end", action="store_true", help="quit when the replay has finished")
    p.add_argument("--screenshot", default=None, help="save a PNG of the window when the replay has finished")
    p.add_argument("--report", default=None, help="write a JSON report when the replay has finished")
    a = p.parse_args(argv)
    if a.speed is not None:
        if a.speed.lower() not in SPEED_ALIASES:
            p.error(f"--speed must be one of 1, 10, max (got {a.speed!r})")
        a.speed = SPEED_ALIASES[a.speed.lower()]
    if a.size:
        try:
            w, h = (int(v) for v in a.size.lower().split("x"))
        except ValueError:
            p.error(f"--size must look like 540x960 (got {a.size!r})")
        a.size = (w, h)
    if a.recording and not os.path.exists(a.recording):
        p.error(f"no such file: {a.recording}")
    return a


def main(argv=None) -> int:
    a = parse_args(argv)
    kivy_env.prepare(headless=a.headless)
    from kivy.config import Config  # noqa: PLC0415 - after the environment is set

    Config.set("input", "mouse", "mouse,disable_multitouch")  # right click must not leave red dots
    if a.size:
        Config.set("graphics", "width", str(a.size[0]))
        Config.set("graphics", "height", str(a.size[1]))
    from app.main_app import PDRApp  # noqa: PLC0415 - creates the window

    app = PDRApp(recording=a.recording, speed=a.speed, out_dir=a.out, data_dir=a.data_dir,
                 exit_at_end=a.exit_at_end, screenshot=a.screenshot, report=a.report)
    app.run()
    if app.exit_code:
        print(f"python -m app: error: {app.error}", file=sys.stderr)
    return app.exit_code


if __name__ == "__main__":
    sys.exit(main())
