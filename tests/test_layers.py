"""The import graph holds its layers: tracking < protocol < peers < sim < sensornet, no
arrow up, no circle, and a project import inside a function only where a comment says which
heavy import it saves (docs/architecture.md, "Layers")."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("tracking", "protocol", "peers", "sim", "sensornet")
KNOWN_CIRCLES: list[list[str]] = []
"""Circles left for their owners, listed by name; none may be added."""


def _modules() -> dict[str, Path]:
    mods = {}
    for layer in LAYERS:
        for f in (ROOT / layer).rglob("*.py"):
            parts = f.relative_to(ROOT).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return mods


def _graph() -> tuple[dict[str, set[str]], dict[str, list[tuple[str, int]]]]:
    """Every module's project imports, and those made inside a function (target, line)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = {m: set() for m in mods}
    inner: dict[str, list[tuple[str, int]]] = {m: [] for m in mods}
    for m, f in mods.items():
        tree = ast.parse(f.read_text(encoding="utf-8"))
        top = {id(n) for n in tree.body}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
            else:
                continue
            for n in names:
                t = resolve(n) if n.split(".")[0] in LAYERS else None
                if t and t != m:
                    edges[m].add(t)
                    if id(node) not in top and (t, node.lineno) not in inner[m]:
                        inner[m].append((t, node.lineno))
    return edges, inner


def _circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_points_up():
    edges, _ = _graph()
    rank = {layer: i for i, layer in enumerate(LAYERS)}
    up = sorted((m, t) for m, ts in edges.items() for t in ts
                if rank[t.split(".")[0]] > rank[m.split(".")[0]])
    assert up == []


def test_no_import_circles():
    edges, _ = _graph()
    assert [c for c in _circles(edges) if c not in KNOWN_CIRCLES] == []


def test_inner_imports_below_sim_say_why():
    """In tracking/, protocol/ and peers/ a project import inside a function carries a
    comment (on its line or the lines just above) naming the heavy import it avoids."""
    _, inner = _graph()
    bare = []
    for m, found in inner.items():
        if m.split(".")[0] not in ("tracking", "protocol", "peers"):
            continue
        lines = _modules()[m].read_text(encoding="utf-8").splitlines()
        for t, line in found:
            near = lines[max(0, line - 4):line]
            if not any("#" in ln for ln in near):
                bare.append(f"{m}:{line} imports {t}")
    assert bare == []


def test_the_checks_see_an_arrow_up_and_a_circle():
    """The checks themselves: a made-up graph with one of each is caught."""
    edges = {"peers.a": {"sim.b"}, "sim.b": {"sim.c"}, "sim.c": {"sim.b"}}
    assert _circles(edges) == [["sim.b", "sim.c"]]
