"""Zenoh key expressions, one namespace per network name (keeps concurrent runs apart).

``sensornet/<network>/scan/<sensor>``, ``.../scans/<host>`` (a host's scan bundles),
``.../estimate/<peer>``, ``.../tracks/<peer>``, ``.../telemetry/<peer>`` (a peer's per-scan
report for live views),
``.../truth``, ``.../alive/<peer>`` (liveliness), ``.../ready/<peer>`` (liveliness, once a
peer sees all its neighbours), ``.../ctl``.
"""

from __future__ import annotations

import re

ROOT = "sensornet"
NAME_MAX = 32
"""The longest name. A network name is also in its CA certificate's common name
(``sensornet <network> CA``, at most 64 characters in X.509) and a run id is a network name
plus a 7-character suffix (:data:`RUN_ID_MAX`); peer names travel in every message, whose
first 192 bytes hold the fields a receiver reads before decoding (peers.admission) and whose
names the codec caps at 64 characters (protocol.codec.Limits.max_name)."""
RUN_ID_MAX = 64
"""The longest Rerun recording id (``--run-id``): it travels in the start and end messages."""
NAME_RULE = (f"1-{NAME_MAX} letters, digits, '_' or '-', starting with a letter or a digit")
"""The rule of :func:`check_name`, as its error messages say it."""
_NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_-]{{0,{NAME_MAX - 1}}}")
_RUN_ID = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_-]{{0,{RUN_ID_MAX - 1}}}")
WORLD = "world"
"""The world's member name: its key and certificate, its ``alive/world`` token, its log."""
ROUTER_PREFIX = "router"
"""Members whose name starts with this are routers (``sensornet router``): trusted to relay
every message (peers.access_control); the run's router logs to ``logs/router.log``."""
RESERVED = (WORLD, "ca")
"""Names a peer may not have: the world's, and the CA's (its files ``ca.key``, ``ca.pem``
sit beside the members' ``<name>.key``, ``<name>.pem``); nor one starting with
:data:`ROUTER_PREFIX`."""


def check_name(name: str, what: str = "name", *, peer: bool = False) -> str:
    """The one rule for names: network names, member names, sensor (= peer) names.

    A name becomes a chunk of Zenoh key expressions (``sensornet/<network>/scan/<sensor>``),
    part of file names (``logs/<name>.log``, ``<name>.key``) and a certificate's common name,
    so it is :data:`NAME_RULE` (no ``/``, ``*``, ``..`` or leading ``-``). With ``peer``
    (a sensor's name), the names of the network's other members are refused as well
    (:data:`RESERVED`, :data:`ROUTER_PREFIX`; case-insensitively, for file systems that are).
    Raises :class:`ValueError` with a one-line message naming the name and the rule."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"invalid {what} {_shown(name)}: a name is {NAME_RULE}")
    low = name.lower()
    if peer and (low in RESERVED or low.startswith(ROUTER_PREFIX)):
        raise ValueError(f"invalid {what} {name!r}: the names {', '.join(RESERVED)} and "
                         f"{ROUTER_PREFIX}* are reserved for the world, the CA and routers")
    return name


def check_run_id(run_id: str) -> str:
    """A Rerun recording id: :data:`NAME_RULE`'s characters, up to :data:`RUN_ID_MAX`."""
    if not isinstance(run_id, str) or not _RUN_ID.fullmatch(run_id):
        raise ValueError(f"invalid run id {_shown(run_id)}: use 1-{RUN_ID_MAX} letters, digits, "
                         f"'_' or '-', starting with a letter or a digit")
    return run_id


def _shown(value) -> str:
    """A bad name for a one-line message: quoted, at most 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}... ({len(str(value))} characters)"


class Keys:
    """Key expressions of one network."""

    def __init__(self, network: str) -> None:
        self.network = check_name(network, "network name")
        self.base = f"{ROOT}/{network}"

    def scan(self, sensor: str = "*") -> str:
        return f"{self.base}/scan/{sensor}"

    def scans(self, host: str = "*") -> str:
        """A peer host's scan bundles (:mod:`protocol.bundle`)."""
        return f"{self.base}/scans/{host}"

    def estimate(self, peer: str = "*") -> str:
        return f"{self.base}/estimate/{peer}"

    def tracks(self, peer: str = "*") -> str:
        return f"{self.base}/tracks/{peer}"

    def telemetry(self, peer: str = "*") -> str:
        """A peer's per-scan telemetry for live views (``sensornet view``): no peer reads it."""
        return f"{self.base}/telemetry/{peer}"

    def telemetries(self, host: str = "*") -> str:
        """A peer host's bundle of its peers' telemetry (:class:`peers.observer.HostReports`)."""
        return f"{self.base}/telemetries/{host}"

    def truth(self) -> str:
        return f"{self.base}/truth"

    def alive(self, peer: str = "*") -> str:
        return f"{self.base}/alive/{peer}"

    def ready(self, peer: str = "*") -> str:
        """Liveliness of a peer that sees all its neighbours (the world waits for these)."""
        return f"{self.base}/ready/{peer}"

    def ctl(self) -> str:
        return f"{self.base}/ctl"

    @staticmethod
    def last(key: str) -> str:
        """The last chunk of a key expression (the peer or sensor name)."""
        return str(key).rsplit("/", 1)[-1]
