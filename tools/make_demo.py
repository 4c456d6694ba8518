"""Regenerate the bundled demo recording ``desktop/data/demo_walk.csv.gz`` from the simulator.

Usage: ``python tools/make_demo.py``.  The file is the simulator's
``demo_walk(seed=0)`` written in the project's format (truth in the header);
``tests/test_simulator.py`` checks that it matches the current simulator.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from core.recording import write_recording
from desktop.simulator import demo_walk

OUT = ROOT / "desktop" / "data" / "demo_walk.csv.gz"

if __name__ == "__main__":
    walk = demo_walk(seed=0)
    write_recording(str(OUT), walk.recording)
    print(f"wrote {OUT}: {walk.recording.duration_s:.1f} s, {walk.truth.n_steps} steps, "
          f"{walk.truth.path_length_m:.1f} m")
