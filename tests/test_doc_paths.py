"""The modules, source paths and dotted names the docs cite exist, so a move cannot leave them
stale (the sim/ reorganisation of issue 37 did: ``python -m sensornet.sim.seed002`` and
``sim/seed003_net.py`` outlived their files).

Read from README.md, docs/*.md and benchmarks/README.md, without importing anything:
``python -m sensornet.X`` resolves (through pyproject's package-dir) to a module with a main
block or a package with ``__main__.py``, inside a package pyproject installs; every
``sim/``, ``peers/``, ``tracking/``, ``protocol/`` or ``sensornet/`` ``.py`` path is a file (an
upper-case placeholder such as ``seed00N`` or ``NAME`` matches any name); a backticked dotted
name ``sensornet.sim.a.b.name`` (or ``sim.a.b``, ``tracking.a.b``, ...) walks packages and
modules down to a name the last module defines or imports at its top level.
"""

from __future__ import annotations

import ast
import functools
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "benchmarks" / "README.md",
        *sorted((ROOT / "docs").glob("*.md"))]
SETUP = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
PACKAGE_DIR: dict[str, str] = {"sensornet": "sensornet", **SETUP["package-dir"]}
PACKAGES = set(SETUP["packages"])

RUN = re.compile(r"python3? -m\s+(sensornet(?:\.\w+)*)(?![.\w<])")  # not `...studies.<name>`
PATH = re.compile(r"(?<![\w./-])((?:sim|peers|tracking|protocol|sensornet)/[\w./-]*?\.py)\b")
DOTTED = re.compile(r"`((?:sensornet\.)?(?:sim|peers|tracking|protocol)(?:\.\w+)+)`")
NOT_NAMES = {"peers.s3"}
"""Backticked dotted text that is no Python name (``peers.s3``: a ``[faults]`` key)."""


def _citations(pattern: re.Pattern) -> list[tuple[str, str]]:
    """Every ``(doc:line, match)`` of ``pattern`` in the docs (a match may span a line break)."""
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        out += [(f"{doc.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}", m.group(1))
                for m in pattern.finditer(text)]
    return out


def _package(dotted: str) -> tuple[str, Path]:
    """The longest package-dir prefix of ``dotted`` and its folder."""
    for prefix in sorted(PACKAGE_DIR, key=len, reverse=True):
        if dotted == prefix or dotted.startswith(prefix + "."):
            return prefix, ROOT / PACKAGE_DIR[prefix]
    raise AssertionError(f"{dotted}: not under any package of pyproject's package-dir")


@functools.cache
def _top_level_names(path: Path) -> frozenset[str]:
    """Names a module binds at its top level: defs, classes, assignments, imports."""
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
    return frozenset(names)


def _resolve(dotted: str) -> tuple[str, Path, str | None]:
    """(module name, its file, the attribute after it or None) of a dotted citation: packages
    and modules as far as they go, then one name the last module must define or import."""
    prefix, folder = _package(dotted)
    module, path = prefix, folder / "__init__.py"
    for part in dotted[len(prefix):].split(".")[1:]:
        if path.name == "__init__.py" and (path.parent / part / "__init__.py").is_file():
            module, path = f"{module}.{part}", path.parent / part / "__init__.py"
        elif path.name == "__init__.py" and (path.parent / f"{part}.py").is_file():
            module, path = f"{module}.{part}", path.parent / f"{part}.py"
        else:
            return module, path, part
    return module, path, None


def test_the_docs_cite_something():
    """The patterns still find what the docs cite (a silently empty scan checks nothing)."""
    assert len(_citations(RUN)) > 20 and len(_citations(PATH)) > 20
    assert len(_citations(DOTTED)) > 20


@pytest.mark.parametrize(("where", "module"), sorted(set(_citations(RUN))))
def test_python_m_modules_exist_and_run(where, module):
    name, path, rest = _resolve(module)
    assert rest is None, f"{where}: python -m {module}: no module {name}.{rest}"
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    assert package in PACKAGES, f"{where}: {module}: package {package} not installed (pyproject)"
    if path.name == "__init__.py":
        assert (path.parent / "__main__.py").is_file(), f"{where}: {module} has no __main__.py"
    else:
        assert "__main__" in path.read_text(encoding="utf-8"), f"{where}: {module} has no main"


@pytest.mark.parametrize(("where", "path"), sorted(set(_citations(PATH))))
def test_cited_source_paths_exist(where, path):
    pattern = re.sub(r"[A-Z]+", "*", path)
    found = (ROOT / path).is_file() if pattern == path else any(ROOT.glob(pattern))
    assert found, f"{where}: {path} does not exist"


@pytest.mark.parametrize(("where", "dotted"),
                         sorted(c for c in set(_citations(DOTTED)) if c[1] not in NOT_NAMES))
def test_cited_dotted_names_exist(where, dotted):
    full = dotted if dotted.startswith("sensornet.") else f"sensornet.{dotted}"
    name, path, attr = _resolve(full)
    assert attr is None or attr in _top_level_names(path), \
        f"{where}: {dotted}: {name} ({path.relative_to(ROOT)}) has no {attr}"
