"""The import graph holds its layers: tracking < protocol < peers < sim < sensornet, no
arrow up, no circle, and a project import inside a function only where a comment says which
heavy import it saves (docs/architecture.md, "Layers")."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("tracking", "protocol", "peers", "sim", "sensornet")
KNOWN_CIRCLES: list[list[str]] = []
"""Circles left for their owners; none may be added (sim.campaign <-> sim.studies.fusion.quality is
gone:
the campaign asks the study registry)."""


def _modules() -> dict[str, Path]:
    mods = {}
    for layer in LAYERS:
        for f in (ROOT / layer).rglob("*.py"):
            parts = f.relative_to(ROOT).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return mods


def _short(name: str) -> str:
    """A module's name in :func:`_modules` (``peers.core``) from its installed name
    (``sensornet.peers.core``)."""
    head, _, rest = name.partition(".")
    return rest if head == "sensornet" and rest.split(".")[0] in LAYERS[:-1] else name


def _graph() -> tuple[dict[str, set[str]], dict[str, list[tuple[str, int]]]]:
    """Every module's project imports, and those made inside a function (target, line)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        name = _short(name)
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


SIM_LAYERS: tuple[tuple[str, ...], ...] = (
    # the ground: standard library only; the registries (kinds, studies, truth models, study
    # formats: the rest finds each by name) and what the command line's parser shows
    ("sim", "sim.bounds", "sim.choices", "sim.plugins", "sim.kinds", "sim.studies",
     "sim.truths", "sim.formats", "sim.scenarios", "sim.campaigns"),
    ("sim.scenario", "sim.scenario."),  # the scenario model and its files
    ("sim.world", "sim.world.", "sim.traffic", "sim.traffic."),  # the world, recorded traffic
    ("sim.kinds.",),  # the peer kinds (the registry's face is on the ground)
    ("sim.run", "sim.run."),  # peers built, twin, processes, launcher, replay, pool
    ("sim.report", "sim.report."),  # plot helpers, one run's figures, HTML
    ("sim.campaign", "sim.campaign."),  # campaigns, sweeps, their results and report
    ("sim.studies.",),  # each seed's reproduction and each measurement, one package each
)
"""The sub-layers of ``sim/``, ground first: a module may import its own sub-layer and those
below, never one above (docs/architecture.md, "Layers"). An entry ending in ``.`` holds the
modules under that package; any other names one module (a package's ``__init__``): a registry
package's face stands on the ground, below the modules it names."""


def _sim_layer(module: str) -> int:
    """The index in :data:`SIM_LAYERS` of a ``sim`` module: an exact entry first, else the
    longest package prefix; :class:`LookupError` for a module no entry places."""
    for i, entries in enumerate(SIM_LAYERS):
        if module in entries:
            return i
    found = [(len(e), i) for i, entries in enumerate(SIM_LAYERS) for e in entries
             if e.endswith(".") and module.startswith(e)]
    if not found:
        raise LookupError(f"{module} is on no sub-layer of SIM_LAYERS")
    return max(found)[1]


def test_every_sim_module_stands_on_one_sub_layer():
    unplaced = []
    for m in _modules():
        if m.split(".")[0] == "sim":
            try:
                _sim_layer(m)
            except LookupError:
                unplaced.append(m)
    assert unplaced == []


def test_no_import_inside_sim_points_up():
    """No ``sim`` module imports one on a higher sub-layer of :data:`SIM_LAYERS` (a kind never
    imports a study, the world never a run, a campaign never a study, ...)."""
    edges, _ = _graph()
    up = sorted((m, t) for m, ts in edges.items() if m.split(".")[0] == "sim" for t in ts
                if t.split(".")[0] == "sim" and _sim_layer(t) > _sim_layer(m))
    assert up == []


def test_the_sub_layer_check_sees_an_arrow_up():
    """The sub-layer order itself: a kind importing a study, the world importing the run and the
    ground importing the scenario are each higher; a study importing a kind is lower."""
    assert _sim_layer("sim.studies.seed003.network") > _sim_layer("sim.kinds.pda")
    assert _sim_layer("sim.run.twin") > _sim_layer("sim.world.build") == _sim_layer("sim.world")
    assert _sim_layer("sim.scenario.model") > _sim_layer("sim.kinds") == _sim_layer("sim.bounds")
    assert _sim_layer("sim.campaign") < _sim_layer("sim.studies.fusion.quality")


def test_no_import_points_up():
    edges, _ = _graph()
    rank = {layer: i for i, layer in enumerate(LAYERS)}
    up = sorted((m, t) for m, ts in edges.items() for t in ts
                if rank[t.split(".")[0]] > rank[m.split(".")[0]])
    assert up == []


def test_no_import_circles():
    edges, _ = _graph()
    assert [c for c in _circles(edges) if c not in KNOWN_CIRCLES] == []


WHY = re.compile(r"#.*\b(?:heavy|optional)\b[\w ]*dependency: *([A-Za-z_][\w.]*)")
"""The comment an import inside a function carries: ``# heavy optional dependency: pyarrow``
(or ``# heavy dependency: NAME`` for a required but slow library, ``# optional dependency:
NAME`` for one that may be missing), naming the third-party module it delays."""


def _statement_lists(tree: ast.AST):
    for node in ast.walk(tree):
        for field in ("body", "orelse", "finalbody", "handlers"):
            stmts = getattr(node, field, None)
            if isinstance(stmts, list) and stmts and isinstance(stmts[0], ast.stmt):
                yield node, stmts


def unexplained_inner_imports(source: str, name: str = "<module>") -> list[str]:
    """Every import inside a function (or class) of ``source`` that has no :data:`WHY` comment
    naming a module outside the project (on its line, the lines of the group of imports it
    starts or belongs to, or the three lines above that group), or whose comment names a module
    other than the third-party one it imports; a standard-library module is never a reason."""
    tree = ast.parse(source)
    lines = source.splitlines()
    module_level = {id(n) for n in tree.body}
    for n in tree.body:  # `try: import x / except ImportError:` at module level is module level
        if isinstance(n, (ast.If, ast.Try)):
            module_level |= {id(m) for m in ast.walk(n)}
    bad = []
    for _, stmts in _statement_lists(tree):
        group_start = None
        for st in stmts:
            if not isinstance(st, (ast.Import, ast.ImportFrom)) or id(st) in module_level:
                group_start = None
                continue
            if group_start is None:
                group_start = st.lineno
            if isinstance(st, ast.ImportFrom) and st.level:
                bad.append(f"{name}:{st.lineno} relative import inside a function")
                continue
            target = st.module if isinstance(st, ast.ImportFrom) else st.names[0].name
            top = target.split(".")[0]
            window = lines[max(0, group_start - 4):st.end_lineno]
            named = [m.group(1) for ln in window if (m := WHY.search(ln))]
            if top in sys.stdlib_module_names:
                bad.append(f"{name}:{st.lineno} imports {target} (standard library: at the top)")
            elif not named or any(n.split(".")[0] in LAYERS or
                                  n.split(".")[0] in sys.stdlib_module_names for n in named):
                bad.append(f"{name}:{st.lineno} imports {target} with no comment naming the "
                           "heavy dependency it delays")
            elif top not in LAYERS and top not in {n.split(".")[0] for n in named}:
                bad.append(f"{name}:{st.lineno} imports {target} but its comment names "
                           f"{named[0]}")
    return bad


def test_every_inner_import_names_the_heavy_dependency_it_delays():
    """An import inside a function exists only to delay a heavy third-party module (rule:
    docs/architecture.md, "Layers"): every other import is at its module's top, where the
    import graph above sees it. The command line keeps start-up quick by loading each
    command's module only when it runs (sensornet.cli.parser.COMMANDS), not by hiding imports."""
    bad = []
    for m, f in _modules().items():
        bad += unexplained_inner_imports(f.read_text(encoding="utf-8"), m)
    assert bad == []


def test_the_inner_import_check_catches_a_bare_one():
    """The check itself: a bare project import, a stdlib one, a comment naming a project
    module and a comment naming the wrong library are caught; a named heavy one passes."""
    src = """
def a():
    from sim.scenario import load_scenario
def b():
    import json
def c():
    from sim import seed004  # heavy dependency: sim.studies.seed004.montecarlo
def d():
    import pyarrow  # heavy optional dependency: matplotlib
def e():
    # heavy optional dependency: sklearn (the baseline)
    from sim import seed004
    from sim.studies.seed004.montecarlo import run_once
def f():
    import matplotlib  # heavy dependency: matplotlib
"""
    found = unexplained_inner_imports(src)
    assert [ln.split(" ")[0] for ln in found] == ["<module>:3", "<module>:5", "<module>:7",
                                                   "<module>:9"]


def _loaded_at_import(start: str) -> set[str]:
    """The modules ``import start`` loads, read from the sources: module-level imports
    (packages' ``__init__`` included), followed through the project; third-party and standard
    library modules by the name imported."""
    mods = _modules()
    seen: set[str] = set()
    todo = [start]
    while todo:
        name = todo.pop()
        parts = name.split(".")
        for i in range(1, len(parts) + 1):  # a package's __init__ runs first
            m = ".".join(parts[:i])
            if m in seen:
                continue
            seen.add(m)
            if _short(m) not in mods:
                continue
            tree = ast.parse(mods[_short(m)].read_text(encoding="utf-8"))
            for node in tree.body:
                if isinstance(node, ast.Import):
                    todo += [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                    todo.append(node.module)
                    todo += [f"{node.module}.{a.name}" for a in node.names
                             if _short(f"{node.module}.{a.name}") in mods]
    return seen


def test_the_command_line_loads_a_command_only_when_it_runs():
    """``import sensornet.cli`` (main, the parser and the table) loads no command module and
    nothing heavy; each command in the table is a module under ``sensornet/cli/commands/``
    with its function, and the parser offers exactly the table's commands."""
    loaded = _loaded_at_import("sensornet.cli")
    heavy = sorted(m for m in loaded if m.split(".")[0] in ("numpy", "scipy", "matplotlib",
                                                             "pyarrow", "rerun", "cryptography")
                   or m.startswith(("sensornet.cli.commands.", "sensornet.sim.scenario",
                                     "sensornet.tracking.")))
    assert heavy == []
    from sensornet.cli.parser import COMMANDS, build_parser

    commands = set(build_parser()._subparsers._group_actions[0].choices)
    assert commands == set(COMMANDS)
    for target in COMMANDS.values():
        module, _, func = target.partition(":")
        tree = ast.parse((ROOT / "sensornet/cli/commands" / f"{module}.py").read_text())
        assert func in {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}, target
    assert "sensornet.cli.commands.run" in _loaded_at_import("sensornet.cli.commands.run")
    assert "numpy" in _loaded_at_import("sensornet.cli.commands.run")  # the check sees them


def test_the_checks_see_an_arrow_up_and_a_circle():
    """The checks themselves: a made-up graph with one of each is caught."""
    edges = {"peers.a": {"sim.b"}, "sim.b": {"sim.c"}, "sim.c": {"sim.b"}}
    assert _circles(edges) == [["sim.b", "sim.c"]]


def test_imports_use_the_installed_names():
    """Every project import names ``sensornet.<folder>`` (the installed name), never the bare
    folder (``peers``, ``sim``, ...): a bare import would load a second copy of a module, and
    an installed wheel has no such top-level package."""
    bare = []
    for folder in (*LAYERS, "tests", "benchmarks"):
        for f in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                bare += [(str(f.relative_to(ROOT)), node.lineno, n) for n in names
                         if n.split(".")[0] in LAYERS[:-1]]
    assert bare == []


def test_the_wheel_holds_every_package_under_its_installed_name():
    """pyproject's package list is every folder with an ``__init__.py`` under its installed
    name, and each of the four folders is mapped to ``sensornet.<folder>`` (a package left
    out would be missing from an installed wheel, not from a checkout)."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = set()
    for layer in LAYERS:
        for init in (ROOT / layer).rglob("__init__.py"):
            parts = init.parent.relative_to(ROOT).parts
            found.add(".".join(parts if parts[0] == "sensornet" else ("sensornet", *parts)))
    assert set(cfg["packages"]) == found
    assert cfg["package-dir"] == {f"sensornet.{d}": d for d in LAYERS[:-1]}
