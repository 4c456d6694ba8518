"""The real phone walks of issue #25: outdoor GPS walks and counted-step clips, with their split.

Folders (under the data root, ``../shared/data``):

``gps_walks_phone/<walk>``                 five outdoor GPS walks (report, :mod:`benchmarks.splits`)
``sensorlogger_gps_walk_ethz/<2023-...>``  the ETH Sensor Logger walk (report)
``phone_walks_more/<walk>``                two GPS walks and a counted clip; split by repository
                                           (``PHONE_WALKS_MORE_REPOS``), ``kind`` from its MANIFEST.tsv
``<extra>/<owner>__<repo>/<walk>``         fetched public recordings (``--extra``, e.g. /work/extdata); the
                                           repository is the folder name, the split
                                           :func:`benchmarks.splits.repo_split`; a ``COUNTS.tsv`` there
                                           (``walk``, ``steps``, ``path_m``, ``carry``) makes a walk a clip

A clip's truth is its stated step count (and path length, a closed loop where the source says so).

Every walk has a ``corpus`` (``shared``: the data root; ``extra``: the ``--extra`` folder) and a carry position
(``carry``): what its source states, else ``not stated`` with the folder README's inference in brackets
(:data:`CARRY`; an extra walk's from the ``carry`` column of the folder's ``MANIFEST.tsv``, or of ``COUNTS.tsv``).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.splits import PHONE_WALKS_MORE_REPOS, repo_split, split_of

GPS_WALK = "gps_walk"
STEP_CLIP = "step_clip"

#: counted clips of ``phone_walks_more``: (steps, path length m, closed loop); from the source's README
PHONE_WALKS_MORE_COUNTS = {"aymdi_data": (168, 116.0, True)}


SHARED = "shared"
EXTRA = "extra"
NOT_STATED = "not stated"

#: carry positions of the shared walks: stated by the source, else the folder README's inference (in brackets)
CARRY = {
    "liatoutou_walk2": "hand (the source's label)",
    "thomasdingemanse_lopen": "not stated (inferred: trouser pocket)",
    "aymdi_data": "not stated (inferred: flat in hand)",
}
#: the same inference for a whole folder
CARRY_FOLDER = {
    "gps_walks_phone": "not stated (inferred: upright, top down: pocket or hanging hand)",
    "sensorlogger_gps_walk_ethz": "not stated (inferred: flat in hand)",
}


@dataclass
class RealWalk:
    dataset: str
    walk: str
    folder: Path
    split: str
    kind: str = GPS_WALK
    repository: str = ""
    steps_counted: int | None = None
    path_m: float | None = None
    closed_loop: bool = False
    info: dict = field(default_factory=dict)
    corpus: str = SHARED
    carry: str = NOT_STATED

    @property
    def name(self) -> str:
        return f"{self.dataset}/{self.walk}"


def _kinds(manifest: Path) -> dict:
    if not manifest.exists():
        return {}
    with open(manifest, newline="", encoding="utf-8") as f:
        return {r["walk_id"]: r.get("kind", GPS_WALK) for r in csv.DictReader(f, delimiter="\t")}


def _manifest_carry(manifest: Path) -> dict:
    """``walk`` -> ``carry`` from an extra folder's MANIFEST.tsv (one row per file; the first row of a walk)."""
    if not manifest.exists():
        return {}
    out = {}
    with open(manifest, newline="", encoding="utf-8") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            if r.get("walk") and r.get("repository"):
                out.setdefault((r["repository"], r["walk"]), r.get("carry") or NOT_STATED)
    return out


def real_walks(root: Path, extra: Path | None = None) -> list[RealWalk]:
    """Every real walk under ``root`` (and ``extra``), in a fixed order."""
    out: list[RealWalk] = []
    for ds, pattern in (("gps_walks_phone", "*"), ("sensorlogger_gps_walk_ethz", "20*")):
        for p in sorted((root / ds).glob(pattern)):
            if p.is_dir():
                out.append(RealWalk(ds, p.name, p, split_of(ds), repository="",
                                    carry=CARRY.get(p.name, CARRY_FOLDER.get(ds, NOT_STATED))))
    more = root / "phone_walks_more"
    kinds = _kinds(more / "MANIFEST.tsv")
    for p in sorted(more.glob("*")):
        if not p.is_dir():
            continue
        info = {"walk": p.name}
        w = RealWalk("phone_walks_more", p.name, p, split_of("phone_walks_more", info), kinds.get(p.name, GPS_WALK),
                     PHONE_WALKS_MORE_REPOS.get(p.name, ""), info=info, carry=CARRY.get(p.name, NOT_STATED))
        if p.name in PHONE_WALKS_MORE_COUNTS:
            w.steps_counted, w.path_m, w.closed_loop = PHONE_WALKS_MORE_COUNTS[p.name]
            w.kind = STEP_CLIP
        out.append(w)
    if extra is not None and extra.is_dir():
        carries = _manifest_carry(extra / "MANIFEST.tsv")
        for repo_dir in sorted(q for q in extra.iterdir() if q.is_dir() and "__" in q.name):
            repo = repo_dir.name.replace("__", "/", 1)
            counts = {}
            if (repo_dir / "COUNTS.tsv").exists():
                with open(repo_dir / "COUNTS.tsv", newline="", encoding="utf-8") as f:
                    counts = {r["walk"]: r for r in csv.DictReader(f, delimiter="\t")}
            for p in sorted(q for q in repo_dir.iterdir() if q.is_dir()):
                w = RealWalk(f"extdata:{repo_dir.name}", p.name, p, repo_split(repo), repository=repo, corpus=EXTRA,
                             carry=carries.get((repo, p.name), NOT_STATED))
                if p.name in counts:
                    c = counts[p.name]
                    w.kind, w.steps_counted = STEP_CLIP, int(c["steps"])
                    w.path_m = float(c["path_m"]) if c.get("path_m") else None
                    w.carry = c.get("carry") or w.carry
                    w.info["carry"] = w.carry
                out.append(w)
    return out
