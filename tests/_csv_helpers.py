"""Writing synthetic one-file CSV recordings for the importer tests (plain or gzip)."""

from __future__ import annotations

import gzip


def write_lines(path, lines: list[str], gz: bool = False):
    """``lines`` joined with newlines (and a final one) into ``path``, gzip-compressed when ``gz``; returns ``path``."""
    text = "\n".join(lines) + "\n"
    if gz:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path
