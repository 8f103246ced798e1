"""The command line's parser keeps its shape: every subcommand, option, default, choice, help
text and argument group of ``build_parser()`` equals the snapshot in
``tests/data/cli_parser_shape.json``, taken from the parser before it was split into a
function per subcommand (issue 37). A deliberate change to a flag regenerates it:
``python tests/test_cli_parser_shape.py`` (then review the diff).

Machine-dependent values (the default ``--jobs``, the default memory budget in a help text)
and registry-fed choices are written as named placeholders, so the snapshot holds on any
machine and a new registry entry does not break it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sensornet.sim.choices import (
    BIRTH_MODELS,
    FUSION_RULES,
    MIXTURE_RULES,
    OMEGA_RULES,
    OOS_POLICIES,
)
from sensornet.sim.kinds import names as kind_names

from sensornet.cli import build_parser, common

SNAPSHOT = Path(__file__).parent / "data" / "cli_parser_shape.json"


def _registries() -> dict[str, list[str]]:
    """Choices lists that come from a registry, by the name the snapshot gives them."""
    return {"BIRTH_MODELS+both": [*BIRTH_MODELS, "both"], "BIRTH_MODELS": list(BIRTH_MODELS),
            "FUSION_RULES": list(FUSION_RULES), "MIXTURE_RULES": list(MIXTURE_RULES),
            "OMEGA_RULES": list(OMEGA_RULES), "OOS_POLICIES": list(OOS_POLICIES),
            "kind_names()": list(kind_names())}


def _type_name(t) -> str | None:
    """A flag's ``type=`` by the name it has in :mod:`sensornet.cli.common` (or a builtin)."""
    if t is None:
        return None
    named = {id(v): k for k, v in vars(common).items() if callable(v)}
    return named.get(id(t), getattr(t, "__name__", repr(t)))


def _plain(value):
    """A JSON-able stand-in for a default or const."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return repr(value)


def _action(a: argparse.Action, group: str | None) -> dict:
    """One argument: everything argparse uses to parse it and print its help."""
    choices = None
    if a.choices is not None and not isinstance(a, argparse._SubParsersAction):
        choices = list(a.choices)
        for name, reg in _registries().items():
            if choices == reg:
                choices = f"<{name}>"
                break
    default = a.default
    if a.dest == "jobs" and default is not None:
        assert default == common._default_jobs(), default
        default = "<_default_jobs()>"
    help_ = a.help
    if isinstance(help_, str):
        help_ = help_.replace(f"{common.default_memory_gb():g} GB", "<default_memory_gb()> GB")
    return {"class": type(a).__name__, "option_strings": list(a.option_strings),
            "dest": a.dest, "default": _plain(default), "const": _plain(a.const),
            "choices": choices, "nargs": a.nargs, "type": _type_name(a.type),
            "metavar": a.metavar, "required": a.required, "help": help_, "group": group}


def parser_shape(parser: argparse.ArgumentParser) -> dict:
    """The whole structure of ``parser`` and its subparsers, in declaration order."""
    group_of = {id(a): g.title for g in parser._action_groups for a in g._group_actions}
    shape: dict = {"prog": parser.prog, "description": parser.description,
                   "defaults": {k: _plain(v) for k, v in parser._defaults.items()},
                   "groups": [g.title for g in parser._action_groups], "actions": [],
                   "subcommands": {}}
    for a in parser._actions:
        shape["actions"].append(_action(a, group_of.get(id(a))))
        if isinstance(a, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in a._choices_actions}
            for name, sp in a.choices.items():
                shape["subcommands"][name] = {"help": helps.get(name), **parser_shape(sp)}
    return shape


def test_the_parser_has_the_snapshot_shape():
    """Every subcommand (in order), option and group is as in the snapshot."""
    want = json.loads(SNAPSHOT.read_text(encoding="utf-8"))
    got = json.loads(json.dumps(parser_shape(build_parser())))
    assert list(got["subcommands"]) == list(want["subcommands"])
    for name in want["subcommands"]:
        assert got["subcommands"][name] == want["subcommands"][name], name
    assert got == want


def test_the_shape_sees_a_changed_flag():
    """The check itself: a changed help text, default or a new flag changes the shape."""
    base = parser_shape(build_parser())
    p = build_parser()
    run = p._subparsers._group_actions[0].choices["run"]
    run.add_argument("--extra", help="x")
    assert parser_shape(p) != base
    p = build_parser()
    sw = p._subparsers._group_actions[0].choices["sweep"]
    next(a for a in sw._actions if a.dest == "policies").default = "nale"
    assert parser_shape(p) != base
    p = build_parser()
    p._subparsers._group_actions[0].choices["view"].set_defaults(nice=3)
    assert parser_shape(p) != base


if __name__ == "__main__":  # regenerate the snapshot after a deliberate change
    SNAPSHOT.parent.mkdir(exist_ok=True)
    SNAPSHOT.write_text(json.dumps(parser_shape(build_parser()), indent=1) + "\n",
                        encoding="utf-8")
    print(f"wrote {SNAPSHOT}", file=sys.stderr)
