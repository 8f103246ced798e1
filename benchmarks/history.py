"""Source files as they were at an older commit, read from the clone's git history, for the
benchmarks' same-run 'before' sides (``benchmarks/before``, ``benchmarks/twin_before.py``). No
copy is kept in the tree; ``git`` and the commit must be in the clone."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_BARE_IMPORT = re.compile(r"^(\s*)(from|import) (tracking|protocol|peers|sim)\b", re.M)
"""Imports of the older tree, whose packages had no ``sensornet.`` prefix yet."""


def old_source(commit: str, path: str, who: str) -> str:
    """The text of ``path`` at ``commit``, its project imports under today's names
    (``sensornet.tracking...``); ``ImportError`` naming ``who`` if git or the commit is
    missing."""
    try:
        text = subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:{path}"],
                              capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise ImportError(f"{who} needs git and commit {commit} in this clone's history "
                          f"({exc})") from None
    return _BARE_IMPORT.sub(r"\1\2 sensornet.\3", text)
