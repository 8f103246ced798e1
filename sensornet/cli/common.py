"""What every command shares: user errors, run folders, flag types, defaults and checks.

Light on purpose (the standard library and small project modules only): the parser imports it,
and ``sensornet --help`` should not wait for NumPy."""

from __future__ import annotations

import argparse
import itertools
import math
import os
import re
import shutil
import socket
import sys
import time
from pathlib import Path

from sensornet.protocol.keys import ROUTER_PREFIX, check_name, check_run_id
from sensornet.sim.bounds import MAX_ROUNDS, MAX_RUNS
from sensornet.sim.studies import DEFAULT_SCENARIO  # noqa: F401  (the parser's and demo's)


class UserError(Exception):
    """A mistake the user can fix (bad file, bad flag): reported in one line, exit code 2."""


# --------------------------------------------------------------------------------------------
# Run folders: unique, and none left empty when a command fails
# --------------------------------------------------------------------------------------------

_CREATED: list[Path] = []
"""Run folders this command created (removed again on failure if nothing was written)."""


def _run_folder(base: str | None, kind: str) -> Path:
    """``--out`` if given, else a new ``runs/<time>-<kind>[-n]`` (two runs in the same second
    get distinct folders: the folder is claimed with an atomic ``mkdir``)."""
    if base:
        root = Path(base)
        if not root.exists():
            root.mkdir(parents=True)
            _CREATED.append(root)
        elif not root.is_dir():
            raise UserError(f"--out {base}: exists and is not a folder")
        return root
    parent = Path("runs")
    parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for n in itertools.count(1):
        root = parent / (f"{stamp}-{kind}" if n == 1 else f"{stamp}-{kind}-{n}")
        try:
            root.mkdir()
        except FileExistsError:
            continue
        _CREATED.append(root)
        return root
    raise AssertionError("unreachable")


def _remove_empty_run_folders() -> None:
    """Remove the folders this command created that hold no file with content."""
    while _CREATED:
        root = _CREATED.pop()
        try:
            if root.is_dir() and not any(p.is_file() and p.stat().st_size > 0
                                         for p in root.rglob("*")):
                shutil.rmtree(root, ignore_errors=True)
        except OSError:
            pass


# --------------------------------------------------------------------------------------------
# Defaults of the budget flags (the checks: sensornet.cli.budgets)
# --------------------------------------------------------------------------------------------

DEFAULT_MAX_POINTS = 5000
"""Expected measurements per scan of one sensor (clutter + targets)."""
DEFAULT_MAX_TARGETS = 500
"""True targets alive at once."""
DEFAULT_MAX_PEERS = 32
"""Peer processes one ``sensornet run`` starts on this machine."""


def _machine_memory_gb() -> float:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    except (ValueError, OSError, AttributeError):
        return 8.0


def default_memory_gb() -> float:
    """Half of this machine's memory."""
    return round(_machine_memory_gb() / 2, 1)


def _default_jobs() -> int:
    return max(1, min(os.cpu_count() or 1, 4))


# --------------------------------------------------------------------------------------------
# Flag values: checked by argparse (one line, exit code 2)
# --------------------------------------------------------------------------------------------


def _number(kind: type, minimum: float, strict: bool, maximum: float | None = None):
    """An argparse ``type=``: a finite ``kind`` above (``strict``) or at least ``minimum``,
    and at most ``maximum`` if given."""
    what = "an integer" if kind is int else "a number"
    bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
    if maximum is not None:
        bound += f" and <= {maximum:,g}"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what} {bound}, got {text!r}") from None
        if (not math.isfinite(value) or value < minimum or (strict and value == minimum)
                or (maximum is not None and value > maximum)):
            raise argparse.ArgumentTypeError(f"must be {what} {bound}, got {text}")
        return value

    parse.__name__ = what  # argparse names the type in some messages
    return parse


POSITIVE_INT = _number(int, 0, strict=True)
NONNEGATIVE_INT = _number(int, 0, strict=False)
POSITIVE_FLOAT = _number(float, 0.0, strict=True)
RUNS = _number(int, 0, strict=True, maximum=MAX_RUNS)
ROUNDS = _number(int, 0, strict=True, maximum=MAX_ROUNDS)


def _network_name(text: str) -> str:
    try:
        return check_name(text, "network name")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _router_name(text: str) -> str:
    try:
        check_name(text, "router name")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not text.startswith(ROUTER_PREFIX):
        raise argparse.ArgumentTypeError(f"invalid router name {text!r}: a router's name "
                                         f"starts with {ROUTER_PREFIX!r}")
    return text


def _run_id(text: str) -> str:
    try:
        return check_run_id(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


_ENDPOINT = re.compile(r"^[a-z][a-z0-9+\-]*/\S+$")


def _endpoint(text: str) -> str:
    """A Zenoh endpoint ``proto/address``, e.g. ``tcp/127.0.0.1:7447``."""
    if not _ENDPOINT.match(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a Zenoh endpoint; use PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
    return text


_VIEWER_URL = re.compile(r"^rerun(\+https?)?://(?P<host>\[[^\]]+\]|[^/:\s]+)(:(?P<port>\d+))?"
                         r"/proxy$")


def _viewer(text: str) -> str | None:
    """``spawn``, ``none``, or a Rerun gRPC URL like ``rerun+http://127.0.0.1:9876/proxy``."""
    if text in ("spawn", "none"):
        return text
    if not _VIEWER_URL.match(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not 'spawn', 'none' or a Rerun URL like "
            f"rerun+http://127.0.0.1:9876/proxy")
    return text


def _existing_file(text: str) -> str:
    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f"file {text!r} not found")
    return text


def viewer_reachable(url: str, timeout: float = 1.0) -> bool:
    """Whether something accepts TCP connections where ``url`` points (a quick probe, so an
    absent viewer costs a warning instead of a ten-second stall at the end of every process)."""
    m = _VIEWER_URL.match(url)
    if m is None:
        return False
    host = m.group("host").strip("[]")
    port = int(m.group("port") or (80 if url.startswith("rerun+http:") else 443))
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def _resolve_viewer(args: argparse.Namespace) -> None:
    """``--viewer none`` is no viewer; an unreachable URL is a warning and no viewer."""
    viewer = getattr(args, "viewer", None)
    if viewer == "none":
        args.viewer = None
    elif viewer and viewer != "spawn" and not viewer_reachable(viewer):
        print(f"sensornet: warning: no Rerun viewer answers at {viewer}; recording to files "
              f"only", file=sys.stderr)
        args.viewer = None


def _tcp_port(ep: str) -> tuple[str, int] | None:
    m = re.match(r"^(?:tcp|tls)/(\[[^\]]+\]|[^:/]+):(\d+)", ep)
    return (m.group(1).strip("[]"), int(m.group(2))) if m else None


def _check_listen_free(endpoints: list[str]) -> None:
    """A ``--listen`` TCP port already in use is a user error before anything starts."""
    for ep in endpoints:
        hp = _tcp_port(ep)
        if hp is None or hp[1] == 0:
            continue
        family = socket.AF_INET6 if ":" in hp[0] else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(hp)
            except OSError as exc:
                raise UserError(f"--listen {ep}: cannot listen there "
                                f"({exc.strerror or exc})") from None
