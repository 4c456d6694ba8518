"""No unsafe loading anywhere (issue #12): user files are parsed, never unpickled or evaluated."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
UNSAFE = re.compile(r"\bimport pickle\b|\bpickle\.|\bcPickle\b|\bdill\b|\bmarshal\.loads?\b|(?<![\w.])eval\(|"
                    r"(?<![\w.])exec\(|allow_pickle\s*=\s*True|yaml\.load\(|yaml\.unsafe_load|shelve\.open|"
                    r"np\.load\(|numpy\.load\(")


def test_no_pickle_eval_or_unsafe_loaders_in_the_product():
    hits = []
    for folder in ("core", "app", "desktop", "benchmarks", "tools"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                code = line.split("#", 1)[0]
                if UNSAFE.search(code):
                    hits.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not hits, "unsafe loading:\n" + "\n".join(hits)


def test_the_pattern_catches_what_it_is_for():
    for bad in ("import pickle", "data = pickle.loads(b)", "x = eval(text)", "np.load(f, allow_pickle=True)",
                "yaml.load(s)"):
        assert UNSAFE.search(bad), bad
    for fine in ("json.loads(text)", "model.evaluate(x)", "literal_eval_free = 1", "self.eval_mode()"):
        assert not UNSAFE.search(fine), fine
