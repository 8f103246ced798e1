"""What the repository and README claim about themselves, checked (issue 26's silent traps)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_gitignore_names_the_key_folders():
    lines = (ROOT / ".gitignore").read_text().splitlines()
    assert {"keys/", "*.key", "*.ed25519"} <= set(lines)


@pytest.mark.network  # runs git
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


@pytest.mark.network  # runs git
@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs a git checkout")
def test_sources_are_not_ignored():
    p = subprocess.run(["git", "check-ignore", "-q", "--no-index", "peers/security.py"],
                       cwd=ROOT, timeout=30)
    assert p.returncode == 1


def _set_claim() -> tuple[set[str], set[str]]:
    """README's two lists: the commands that take ``--set`` and those that take none."""
    import re

    text = " ".join((ROOT / "README.md").read_text().split())
    m = re.search(r"The commands that play a scenario, (.*?) take `--set KEY=VALUE`.*?; a "
                  r"campaign file holds its overrides in its `\[set\]` table, and (.*?) take "
                  r"no `--set`", text)
    assert m, "README's --set sentence is gone"
    return set(re.findall(r"`([a-z]+)`", m.group(1))), set(re.findall(r"`([a-z]+)`",
                                                                      m.group(2)))


def test_readme_says_exactly_which_commands_take_set():
    """README claimed every command takes --set; campaign, report, keys, scenario and router
    do not. Its lists now are the parser's, every command in one of them."""
    import argparse

    from sensornet.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    takes = {name for name, sp in sub.choices.items()
             if any("--set" in a.option_strings for a in sp._actions)}
    with_set, without = _set_claim()
    assert with_set == takes
    assert without == set(sub.choices) - takes
    assert "Every command takes `--set" not in (ROOT / "README.md").read_text()


def _project_texts() -> list[Path]:
    skip = {".git", ".venv", "runs", "build", "dist", "node_modules"}
    return [p for p in ROOT.rglob("*") if p.suffix in (".py", ".md", ".toml", ".yml")
            and p.is_file() and not skip & set(p.relative_to(ROOT).parts)
            and not any(part.endswith(".egg-info") for part in p.parts)]


def test_files_cite_only_docs_the_project_has():
    """Scenario and campaign files and docstrings cited ALGORITHMS.md, which the project does
    not contain: they cite docs/algorithms.md (by section name) and docs/seed00N.md."""
    import re

    texts = _project_texts()
    names = {p.relative_to(ROOT).as_posix() for p in texts}
    assert {"sim/scenarios/seed004.toml", "sim/campaigns/loss-sweep.toml",
            "tracking/gmphd.py"} <= names
    here = Path(__file__).name
    cites = [(p, p.read_text(errors="replace")) for p in texts if p.name != here]
    stale = [p.relative_to(ROOT).as_posix() for p, t in cites
             if any("ALGORITHMS.md" in ln and '"ALGORITHMS.md" not in' not in ln
                    for ln in t.splitlines())]
    assert not stale, stale
    headings = [ln[3:] for ln in (ROOT / "docs" / "algorithms.md").read_text().splitlines()
                if ln.startswith("## ")]
    sections = 0
    for p, t in cites:
        for doc in set(re.findall(r"\bdocs/[\w./-]+\.md\b", t)):
            assert (ROOT / doc).is_file(), (p, doc)
        for m in re.finditer(r'docs/algorithms\.md ((?:"[^"\n]+"(?:, )?)+)', t):
            for name in re.findall(r'"([^"]+)"', m.group(1)):
                sections += 1
                assert any(h == name or h.startswith((name + " (", name + " —"))
                           for h in headings), (p.relative_to(ROOT).as_posix(), name)
    assert sections >= 20  # the docstrings' citations are checked, not skipped
