"""Bags (``sensornet record`` files, :mod:`sensornet.bag`) and the twin: a twin run written as
the bag ``sensornet record`` would have made of it (:func:`twin_bag`), and fresh peers fed a
bag's world part on the twin's virtual clock (:func:`play_twin`), what peers started by hand
compute from ``sensornet play --only world``, deterministically.

A bag's items are what the network carried, with their receive times: the world's part (its
scans, truth, control and ``alive/world`` token, :func:`sensornet.bag.is_world`) becomes the
twin's world events at the recorded times (relative to the first item), each scan to its
sensor's peer, the truth and control to every peer; the peers then exchange their own
estimates on the twin as usual.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path

from sensornet.bag import Bag, Item, is_world
from sensornet.peers.core import Publish
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import Rejected
from sensornet.protocol.keys import ROOT, WORLD, Keys
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import TwinResult, run_twin, world_events
from sensornet.sim.scenario import Scenario, ScenarioError, load_document, parse_overrides
from sensornet.sim.world import generate_run, plot_ages

EPOCH = 1_700_000_000.0
"""The receive time (s since the epoch) a twin bag gives the twin's time 0."""


def bag_scenario(meta: Mapping[str, str]) -> Scenario | None:
    """The run's scenario a bag's metadata holds (``sensornet record --scenario``: its text,
    file name and ``--set`` items), None if it holds none; a bad one raises as loading does
    (:class:`sensornet.sim.scenario.ScenarioError`)."""
    text = meta.get("scenario_text")
    if not text:
        return None
    name = meta.get("scenario_file") or "scenario.toml"
    sets = parse_overrides(json.loads(meta.get("overrides") or "[]"))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{name} (in the bag): invalid TOML: {exc}") from None
    return load_document(data, name, sets, Path(name).stem, f"bag:{name}")


def bag_events(items: Sequence[Item], names: Sequence[str]) -> list[tuple]:
    """The twin's world events ``(t, kind, target, *payload)`` of a bag's world part (times
    from its first item); a scan goes to its sensor's peer, truth and control to every peer of
    ``names``. A bag whose items are not all the world's (``select(items, "world")`` first),
    or with scan bundles (``scans/<host>``, a host's), is a one-line :class:`ValueError`."""
    if not items:
        return []
    t0 = items[0].t
    out: list[tuple] = []
    for it in items:
        if not is_world(it):
            raise ValueError(f"{it.key}: not the world's (play only the world's part to fresh "
                             f"peers: select(items, 'world'))")
        parts = it.key.split("/")
        t = it.t - t0
        if it.alive is not None:
            out += [(t, "live", n, WORLD, it.alive) for n in names]
        elif parts[2] == "scan":
            if len(parts) == 4 and parts[3] in names:
                out.append((t, "msg", parts[3], it.key, it.payload))
        elif parts[2] == "scans":
            try:
                bundle = unpack_bundle(it.payload)
            except Rejected as exc:
                raise ValueError(f"{it.key}: not a scan bundle ({exc.reason})") from None
            base = "/".join(parts[:2])
            out += [(t, "msg", s, f"{base}/scan/{s}", z) for s, z in bundle.entries
                    if s in names]
        else:  # truth, ctl: every peer subscribes
            out += [(t, "msg", n, it.key, it.payload) for n in names]
    return out


def play_twin(items: Sequence[Item], scn: Scenario, run: int = 0,
              network: str | None = None) -> TwinResult:
    """Fresh peers of ``scn`` (run ``run``, as ``sensornet peer --run``) fed a bag's world part
    on the twin's clock, with the scenario's link behaviour; ``network``: the bag's (default:
    its keys')."""
    if network is None:
        network = next((it.key.split("/")[1] for it in items
                        if it.key.startswith(f"{ROOT}/")), "twin")
    peers = {n: make_peer(scn, n, run, network=network) for n in scn.sensor_names}
    return run_twin(scn, run, peers=peers, network=network,
                    world=bag_events(items, scn.sensor_names))


class _Tap:
    """A peer core whose publications are noted as bag items (the rest goes to the core)."""

    def __init__(self, core, keys: Keys, items: list[Item]) -> None:
        self._core, self._keys, self._items = core, keys, items

    def __getattr__(self, name: str):
        return getattr(self._core, name)

    def _note(self, now: float, outputs: list) -> list:
        for o in outputs:
            if isinstance(o, Publish):
                key = f"{self._keys.base}/{o.channel}/{self._core.name}"
                self._items.append(Item(EPOCH + now, key, o.payload))
        return outputs

    def receive(self, key: str, payload: bytes, now: float, admitted: bool = False) -> list:
        return self._note(now, self._core.receive(key, payload, now, admitted))

    def liveliness(self, name: str, joined: bool, now: float) -> list:
        return self._note(now, self._core.liveliness(name, joined, now))

    def tick(self, now: float) -> list:
        return self._note(now, self._core.tick(now))

    def completed(self, now: float) -> list:
        return self._note(now, self._core.completed(now))


def twin_bag(path: Path, scn: Scenario, run: int = 0, network: str = "twin") -> TwinResult:
    """Run the twin and write what its network carried to ``path`` as ``sensornet record``
    would have: the world's tokens and messages, each peer's ``alive``/``ready`` tokens and
    every estimate and track it published (receive time: :data:`EPOCH` + the twin's time).
    Returns the twin's result (the peers are wrapped: use its ``tracks``, ``ospa``)."""
    keys = Keys(network)
    names = scn.sensor_names
    truth, scans = generate_run(scn, run)
    interval = scn.scan_period / scn.network.speed
    world = world_events(scn, truth, scans, keys, interval, (), (), plot_ages(scn, run))
    items: list[Item] = []
    seen: set[tuple] = set()
    for t, kind, _target, *payload in world:  # the twin delivers a copy to every peer
        key = f"{keys.base}/alive/{WORLD}" if kind == "live" else payload[0]
        note = (t, key, payload[1])  # (time, key, joined or bytes)
        if note in seen:
            continue
        seen.add(note)
        items.append(Item(EPOCH + t, key, alive=payload[1]) if kind == "live"
                     else Item(EPOCH + t, key, payload[1]))
    for n in names:
        items += [Item(EPOCH, keys.alive(n), alive=True), Item(EPOCH, keys.ready(n), alive=True)]
    peers = {n: _Tap(make_peer(scn, n, run, network=network), keys, items) for n in names}
    result = run_twin(scn, run, peers=peers, network=network, world=world)
    end = max(it.t for it in items)
    for n in names:
        items += [Item(end, keys.ready(n), alive=False), Item(end, keys.alive(n), alive=False)]
    bag = Bag(Path(path), network)
    bag.open()
    try:
        for it in sorted(items, key=lambda it: it.t):  # stable: equal times in their order
            bag.write_item(it)
    finally:
        bag.close()
    return result
