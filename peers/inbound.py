"""What an admitted message carries from the transport to the core: its key parsed once.

The transport parses a message's key for admission (:func:`peers.admission.parse_key`); the
inbox item keeps that :class:`peers.admission.Route`, so neither the runtime (channel, link
faults) nor the core parses it again (issue 37 item 5). The item is still the plain tuple
``("msg", key, payload)`` every consumer of the inbox reads and compares.
"""

from __future__ import annotations

from sensornet.peers.admission import Route, parse_key


class Delivered(tuple):
    """``("msg", key, payload)`` as admitted, with ``route``: its key as admission parsed it."""

    route: Route | None

    def __new__(cls, key: str, payload: bytes, route: Route | None) -> Delivered:
        item = super().__new__(cls, ("msg", key, payload))
        item.route = route
        return item


def delivered(item: tuple, network: str) -> tuple:
    """``item`` from an inbox as a :class:`Delivered` if it is a message: a transport's comes
    with its route; a plain ``("msg", key, payload)`` (a driver or test feeding the queue
    itself) has its key parsed here, once. Other items (``live``, ``stop``) as they are."""
    if type(item) is Delivered or item[0] != "msg":
        return item
    return Delivered(item[1], item[2], parse_key(item[1], network))
