"""Entry point of the PDR Tracker app.

* Android (buildozer / python-for-android runs this file): live tracking.
* Desktop: ``python main.py [RECORDING] [--speed 1|10|max]`` replays a
  recording (same options as ``python -m app --help``).

The version is single-sourced in ``core/__init__.py`` (``buildozer.spec``
reads it from there with ``version.regex``).
"""

import sys

from app.__main__ import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
