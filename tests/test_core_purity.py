"""core/ must run on the phone: numpy only at run time, never kivy, jnius, plyer or scipy, nor desktop/."""

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[1] / "core"
FORBIDDEN = {"kivy", "jnius", "plyer", "scipy", "matplotlib", "pandas", "android", "desktop", "benchmarks", "tools"}
# desktop-only modules of core that may import a desktop library *inside a function*
LAZY_OK = {"export.py": {"gpxpy"}}


def _imports(tree, top_level_only):
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module.split(".")[0]


def test_no_forbidden_imports_anywhere_in_core():
    bad = []
    for f in CORE.rglob("*.py"):
        tree = ast.parse(f.read_text())
        allowed = LAZY_OK.get(f.name, set())
        for name in _imports(tree, top_level_only=False):
            if name in FORBIDDEN and name not in allowed:
                bad.append(f"{f.relative_to(CORE)} imports {name}")
        for name in _imports(tree, top_level_only=True):
            if name in allowed:
                bad.append(f"{f.relative_to(CORE)} imports {name} at module level")
    assert not bad, bad


def test_importing_and_running_core_loads_no_forbidden_module():
    code = (
        "import sys, core, core.pdr.pipeline, core.recording, core.export, core.importers\n"
        "from core.pdr.pipeline import Pipeline\n"
        "from core.recording import read_recording\n"
        "Pipeline().run(read_recording('desktop/data/demo_walk.csv.gz'))\n"
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {sorted(FORBIDDEN)!r})\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=CORE.parent, check=True)
    assert out.stdout.strip() == ""
