"""``sensornet router``: a Zenoh router from the Python package (no ``zenohd`` is available from
the package index), for networks whose members cannot all reach each other.

Members connect to it as Zenoh clients (``mode: "client"`` in a ``--config`` file, or a session
of their own). In secure mode it holds a ``router*`` member certificate of the network's CA
(``sensornet keys NETWORK --out DIR --members router``): it speaks mutual TLS only and enforces
the network's access control at its ingress, by each client's certificate name; the members
trust the ``router*`` names to relay (a member behind a router sees every message as the
router's).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import zenoh
from sensornet.peers.security import (
    OBSERVER_PREFIX,
    ROUTER_PREFIX,
    WORLD,
    Security,
    SecurityError,
    check_endpoints,
    keys_network,
)
from sensornet.peers.session import SessionError, zenoh_config


def router_security(folder: str | Path, name: str, network: str | None = None):
    """The router's :class:`peers.security.Security` from a keys folder (roster from its
    ``members.json``: the world, the routers, the read-only observers, every other name a
    peer)."""
    made_for = keys_network(folder)
    if network and network != made_for:
        raise SecurityError(f"--secure {folder}: keys of network {made_for!r}, not of "
                            f"{network!r}")
    roster = Path(folder) / "members.json"
    names = json.loads(roster.read_text()).get("members", []) if roster.is_file() else []
    peers = [n for n in names if n != WORLD
             and not n.startswith((ROUTER_PREFIX, OBSERVER_PREFIX))]
    if not name.startswith(ROUTER_PREFIX):
        raise SecurityError(f"a router's member name must start with {ROUTER_PREFIX!r}, "
                            f"not {name!r}")
    return Security.load(folder, name, made_for, peers)


def run_router(listen: Sequence[str], connect: Sequence[str] = (),
               config_file: str | None = None, security=None,
               stop: threading.Event | None = None, say=None) -> None:
    """Run a router until SIGINT/SIGTERM (or ``stop`` is set)."""
    say = say or (lambda line: None)
    conf = zenoh_config(listen, connect, config_file, security=security)
    conf.insert_json5("mode", '"router"')
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, lambda signum, frame: stop.set())
    try:
        session = zenoh.open(conf)
    except Exception as exc:
        raise SessionError(f"cannot start the router (listen {list(listen)}): {exc}") from None
    try:
        who = f" as {security.member} of network {security.network}" if security else ""
        say(f"router: listening on {', '.join(listen)}{who}")
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    say("router: stopped")


def serve(listen: list[str], connect: list[str], config: str | None, secure: str | None,
          name: str = "router", network: str | None = None) -> None:
    """Run a router from command-line values (``secure``: the keys folder), printing its
    lines; what ``sensornet router`` and ``python -m sensornet.sim.run.router`` both do."""
    security = None
    if secure:
        security = router_security(secure, name, network)
        check_endpoints([*listen, *connect])
    run_router(listen, connect, config, security, say=lambda line: print(line, flush=True))


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.run.router``: ``sensornet router`` without the CLI's imports (SciPy
    and the
    rest take seconds to load on a busy machine: a routed run restarts its router this way)."""
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.run.router", description=__doc__)
    ap.add_argument("--listen", action="append", required=True, metavar="ENDPOINT")
    ap.add_argument("--connect", action="append", metavar="ENDPOINT")
    ap.add_argument("--config")
    ap.add_argument("--secure", metavar="DIR")
    ap.add_argument("--name", default="router")
    ap.add_argument("--network")
    args = ap.parse_args(argv)
    try:
        serve(args.listen, args.connect or [], args.config, args.secure, args.name, args.network)
    except SessionError as exc:
        print(f"{ap.prog}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
