"""Environment for Kivy, set before ``import kivy`` (this module imports no Kivy).

* ``KIVY_NO_ARGS=1`` always: the app parses its own command line (argparse),
  Kivy must not read ``sys.argv`` (nor pytest's).
* ``headless=True`` (tests, screenshots on a machine without a display):
  SDL's ``offscreen`` video driver, which renders through Mesa EGL (no Xvfb),
  no console log, Kivy's default config and a throw-away ``KIVY_HOME`` so the
  user's ``~/.kivy`` is neither read nor written.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile


def prepare(*, headless: bool = False, kivy_home: str | None = None, quiet: bool | None = None) -> None:
    os.environ.setdefault("KIVY_NO_ARGS", "1")
    if quiet if quiet is not None else headless:
        os.environ.setdefault("KIVY_NO_CONSOLELOG", "1")
    if headless:
        os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
        os.environ.setdefault("KIVY_NO_FILELOG", "1")
        os.environ.setdefault("KIVY_USE_DEFAULTCONFIG", "1")
        if "KIVY_HOME" not in os.environ:
            home = kivy_home or tempfile.mkdtemp(prefix="kivyhome-")
            os.environ["KIVY_HOME"] = home
            if not kivy_home:  # ours: removed when this process ends (subprocesses inherit it)
                atexit.register(shutil.rmtree, home, True)
    elif kivy_home:
        os.environ.setdefault("KIVY_HOME", kivy_home)
