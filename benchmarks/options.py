"""The options every benchmark module takes the same way (issue #29): ``--data``, ``--only``, ``--no-write``.

* ``--data DIR`` (alias ``--data-root``): the data root, laid out as ``../shared/data`` (default: that folder
  beside the checkout).  Recordings the split declarations (:mod:`benchmarks.splits`) do not name are report.
* ``--only NAMES``: comma-separated (or repeated) parts of recording names, or dataset names: only the
  recordings whose name (or dataset) contains one of them.  A subset never rewrites the committed results:
  ``--only`` implies ``--no-write``.
* ``--no-write``: nothing tracked by git is touched: the results files (and plots) go to
  ``out/benchmarks/<module>/`` instead of ``benchmarks/``.

A recording that fails is counted and listed in the results (:func:`failed_row`), never dropped from a
median: its errors count as +inf (the company's rule).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.metrics import median_counting_failures

REPO = Path(__file__).resolve().parent.parent
HERE = REPO / "benchmarks"


def add_common(ap: argparse.ArgumentParser, *, what: str = "recording names") -> None:
    """Add ``--data``, ``--only`` and ``--no-write`` to ``ap``."""
    ap.add_argument("--data", "--data-root", dest="data", type=Path, default=None,
                    help="the data root, laid out as ../shared/data (default: that folder beside the checkout)")
    ap.add_argument("--only", action="append", default=None, metavar="NAMES",
                    help=f"comma-separated parts of {what} (repeatable): run that subset; implies --no-write")
    ap.add_argument("--no-write", action="store_true",
                    help="write the results under out/benchmarks/<module>/, touch nothing tracked by git")


def data_root(args) -> Path:
    """The data root: ``--data`` or the default; a missing folder is said on stderr (every real recording would be
    skipped without it, and a run of nothing must not look like a run)."""
    root = Path(args.data) if getattr(args, "data", None) else default_data_root()
    if not root.is_dir():
        print(f"benchmarks: the data root {root} does not exist: no real recording can be read "
              "(give --data DIR, the folder laid out as ../shared/data)", file=sys.stderr)
    return root


def only_keys(args) -> list[str] | None:
    """The ``--only`` substrings, or None for everything."""
    raw = getattr(args, "only", None)
    if not raw:
        return None
    if isinstance(raw, str):
        raw = [raw]
    keys = [k.strip() for item in raw for k in str(item).split(",") if k.strip()]
    return keys or None


def selected(keys: list[str] | None, *names: str) -> bool:
    """True when no ``--only`` was given or one of ``names`` contains one of its parts."""
    return keys is None or any(k in str(n) for k in keys for n in names if n)


def writes_committed(args) -> bool:
    """Whether this run may rewrite the committed results (a full run without ``--no-write``)."""
    return not getattr(args, "no_write", False) and only_keys(args) is None


def out_dir(module: str) -> Path:
    """``out/benchmarks/<module>/`` (created): where a ``--no-write`` or ``--only`` run writes."""
    d = REPO / "out" / "benchmarks" / module
    d.mkdir(parents=True, exist_ok=True)
    return d


def result_path(args, committed: Path, module: str) -> Path:
    """``committed`` for a full run, else the same file name under :func:`out_dir`."""
    return Path(committed) if writes_committed(args) else out_dir(module) / Path(committed).name


def git_rev() -> str:
    """The checkout's short commit (``git rev-parse --short HEAD``), ``""`` when git cannot say."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip()
    except OSError:
        return ""


#: how a non-finite float is written in a results file: JSON has no NaN or Infinity, and ``null`` already means
#: "not measured" there, so a counted failure (+inf) or an unscored value (nan) is kept apart as a string
NONFINITE_TEXT = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def jsonable(x, digits: int | None = 4, nonfinite_as_null: bool = False):
    """Results as JSON can hold them: dict keys as strings, numpy numbers as Python's, floats rounded to
    ``digits`` decimals (None: as they are), a non-finite float as the string ``"nan"``, ``"inf"`` or ``"-inf"``
    (:func:`read_json` turns them back; ``None`` stays ``null``).  Standard JSON that other tools open.
    ``nonfinite_as_null``: a non-finite float as ``None`` instead (what :mod:`benchmarks.walkdir` hands its own
    markdown, which has no failure medians to tell apart)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v, digits, nonfinite_as_null) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v, digits, nonfinite_as_null) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist(), digits, nonfinite_as_null)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        if not math.isfinite(v):
            return None if nonfinite_as_null else "nan" if math.isnan(v) else "inf" if v > 0 else "-inf"
        return v if digits is None else round(v, digits)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_json(path: Path, obj, *, digits: int | None = 4, indent: int | None = 1) -> None:
    """``obj`` through :func:`jsonable` into ``path`` (strict JSON: a NaN left anywhere raises)."""
    Path(path).write_text(json.dumps(jsonable(obj, digits), indent=indent, allow_nan=False) + "\n")


def _restored(x):
    if isinstance(x, dict):
        return {k: _restored(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_restored(v) for v in x]
    if isinstance(x, str) and x in NONFINITE_TEXT:
        return NONFINITE_TEXT[x]
    return x


def read_json(path: Path):
    """A results file as :func:`write_json` wrote it, its ``"nan"``/``"inf"``/``"-inf"`` strings floats again
    (an older file's bare ``NaN``/``Infinity`` reads too)."""
    return _restored(json.loads(Path(path).read_text()))


def failed_row(name: str, split: str, exc: BaseException, **extra) -> dict:
    """A row for a recording that failed: named, counted, its error kept (one line and the last frame)."""
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    return {"name": name, "split": split, "failed": f"{type(exc).__name__}: {exc}{where}", **extra}


def failures_line(rows) -> str:
    """``"2 failed: a (ValueError: ...), b (...)"`` or ``""``."""
    bad = [r for r in rows if r.get("failed")]
    return "" if not bad else f"{len(bad)} failed: " + "; ".join(f"{r['name']} ({r['failed']})" for r in bad)


#: the median with failures (None, nan) as +inf, never dropped; nan only when there is nothing: the one in
#: :mod:`benchmarks.metrics`, under the name the indoor benchmark has used
median_inf = median_counting_failures


def task_name(task) -> str:
    """A readable name for a task tuple (paths by their last two parts, no None)."""
    parts = task if isinstance(task, (tuple, list)) else (task,)
    out = []
    for p in parts:
        if p is None or isinstance(p, dict):
            continue
        s = str(p)
        out.append("/".join(Path(s).parts[-2:]) if "/" in s else s)
    return " ".join(out)


class Guarded:
    """``fn(task)`` that returns a :func:`failed_row` instead of raising (picklable for process pools): one
    bad recording neither stops the run nor vanishes from it."""

    def __init__(self, fn, split: str = "?"):
        self.fn = fn
        self.split = split

    def __call__(self, task):
        try:
            return self.fn(task)
        except Exception as e:
            return failed_row(task_name(task), self.split, e)


def split_failed(rows) -> tuple[list, list]:
    """``(failed rows, the others)``."""
    rows = list(rows)
    return [r for r in rows if isinstance(r, dict) and r.get("failed")], [r for r in rows
                                                                          if not (isinstance(r, dict) and r.get("failed"))]


def failures_markdown(failed) -> list[str]:
    """Markdown lines listing the failed recordings (empty when none)."""
    if not failed:
        return []
    return ["", f"### {len(failed)} recording(s) failed (counted as failed, +inf, never dropped silently)", "",
            "| recording | split | error |", "|---|---|---|"] + [
        f"| {r['name']} | {r.get('split', '?')} | {str(r['failed']).replace('|', '/')} |" for r in failed] + [""]
