"""Zenoh key expressions, one namespace per network name (keeps concurrent runs apart).

``sensornet/<network>/scan/<sensor>``, ``.../estimate/<peer>``, ``.../tracks/<peer>``,
``.../truth``, ``.../alive/<peer>`` (liveliness), ``.../ready/<peer>`` (liveliness, once a
peer sees all its neighbours), ``.../ctl``.
"""

from __future__ import annotations

import re

_NAME = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")
ROOT = "sensornet"


def check_name(name: str, what: str = "name") -> str:
    """A network, peer or sensor name usable in a key expression (letters, digits, _ and -)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"invalid {what} {name!r}: use 1-64 letters, digits, '_' or '-'")
    return name


class Keys:
    """Key expressions of one network."""

    def __init__(self, network: str) -> None:
        self.network = check_name(network, "network name")
        self.base = f"{ROOT}/{network}"

    def scan(self, sensor: str = "*") -> str:
        return f"{self.base}/scan/{sensor}"

    def estimate(self, peer: str = "*") -> str:
        return f"{self.base}/estimate/{peer}"

    def tracks(self, peer: str = "*") -> str:
        return f"{self.base}/tracks/{peer}"

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
