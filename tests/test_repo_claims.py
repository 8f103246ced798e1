"""What the repository and README claim about themselves, checked (issue 26's silent traps)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs a git checkout")
@pytest.mark.parametrize("path", ["keys/lab/ca.key", "keys/lab/s1.key", "keys/lab/s1.ed25519",
                                  "keys/compose/router.key", "keys/lab/ca.pem",
                                  "somewhere/else/world.key", "runs/x-run/keys/ca.key"])
def test_key_folders_are_git_ignored(path):
    """``sensornet keys --out keys/lab`` writes ca.key next to the members' keys: git ignores
    the folder (and a private key anywhere)."""
    p = subprocess.run(["git", "check-ignore", "-q", "--no-index", path], cwd=ROOT,
                       timeout=30)
    assert p.returncode == 0, f"{path} is not git-ignored"


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs a git checkout")
def test_sources_are_not_ignored():
    p = subprocess.run(["git", "check-ignore", "-q", "--no-index", "peers/security.py"],
                       cwd=ROOT, timeout=30)
    assert p.returncode == 1
