"""Record what a peer's core was given, and replay it offline, bit for bit.

The sans-I/O core (:class:`peers.core.PeerCore`) is a function of its inputs: the bytes it
received (after the transport's admission and the injected link faults), the liveliness
changes, the clock at which deadlines fired, and the end of the run. A recording is exactly
that, in an MCAP file (the robotics tools' container; JSON records with a JSON Schema per
topic, :data:`SCHEMAS`; zstd chunks), plus the tracks the peer published, so a replay can check
itself. Each message is there twice: its exact bytes (``payload``, base64, what a replay feeds)
and every field decoded (``message``, protocol.json_fields), so ``mcap``'s reader and
``json.loads`` alone read it. With :meth:`Recorder.attach` the file also holds the truth the
peer scored against (``truth``) and its picture as a Foxglove ``foxglove.SceneUpdate``
(``/scene``: tracks, 2-sigma ellipses, truth, sensors; peers.foxglove_scene).
:func:`replay_with` feeds the same calls to the same peer, which its caller builds
(:func:`sim.run.replay.replay` rebuilds it from the scenario stored in the file): the fused
tracks come out identical to the last bit. With changed settings (``--set``) it is a what-if
run of one peer on the inputs it really had.
"""

from __future__ import annotations

import base64
import json
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
import numpy as np
from sensornet.peers.core import PeerCore, Publish
from sensornet.peers.foxglove_scene import SCENE_SCHEMA, scene_update
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.json_fields import MESSAGE_SCHEMA, dumps, fields

TOPICS = ("receive", "liveliness", "tick", "finish", "tracks")
"""The topics a replay feeds (the core's inputs and its published tracks)."""
EXTRA = ("truth", "/scene", "telemetry")
"""Topics for readers only (not fed by a replay): the truth scored against, the scene, and the
peer's per-scan telemetry (its tracks and report, as put on ``telemetry/<peer>``: what the
live view draws the fused marks, events and health series from; ``sensornet view
--from-mcap``)."""
META = "sensornet"
_T = {"type": "number", "description": "the peer's clock (s since the epoch) at the call"}
_BYTES = {"type": "string", "contentEncoding": "base64",
          "description": "the message's bytes as received or published (protocol.codec)"}
_MESSAGE = {**MESSAGE_SCHEMA, "type": ["object", "null"],
            "description": "every field of the payload, decoded (null: it did not decode)"}
SCHEMAS = {
    "receive": {"t": _T, "key": {"type": "string", "description": "Zenoh key expression"},
                "payload": _BYTES, "message": _MESSAGE},
    "liveliness": {"t": _T, "name": {"type": "string"}, "joined": {"type": "boolean"}},
    "tick": {"t": _T},
    "finish": {"t": _T},
    "tracks": {"t": _T, "k": {"type": "integer", "description": "scan index"},
               "payload": _BYTES, "message": _MESSAGE},
    "truth": {"t": _T, "k": {"type": "integer", "description": "scan index"},
              "ids": {"type": ["array", "null"], "description": "(m,) true target ids"},
              "states": {"type": "array", "description": "(m, d) true states"}},
    "telemetry": {"t": _T, "payload": {
        **_BYTES, "description": "one telemetry message's bytes as put on telemetry/<peer> (a "
                                 "protocol.bundle of the scan's tracks and Telemetry report)"}},
}
"""Each topic's record as a JSON Schema (MCAP ``jsonschema`` schemas over ``json`` messages:
the mcap tools and Foxglove decode them without our code; floats are written by ``repr``,
which round-trips exactly, and bytes as base64, so a replay is still bit for bit). The scene
topic ``/scene`` has Foxglove's ``foxglove.SceneUpdate`` schema."""


class Recorder:
    """Writes one peer's core inputs (and its published tracks) to an MCAP file."""

    def __init__(self, path: Path, meta: dict[str, str]) -> None:
        # heavy dependency: mcap (only --record and replay need it)
        from mcap.writer import CompressionType, Writer

        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._fh = path.open("wb")
        self._w = Writer(self._fh, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="sensornet")
        self._ch = {}
        for topic, props in SCHEMAS.items():
            schema = json.dumps({"title": f"sensornet.{topic}", "type": "object",
                                 "properties": props, "required": list(props),
                                 "additionalProperties": False}).encode()
            sid = self._w.register_schema(f"sensornet.{topic}", "jsonschema", schema)
            self._ch[topic] = self._w.register_channel(topic, "json", sid)
        sid = self._w.register_schema("foxglove.SceneUpdate", "jsonschema",
                                      json.dumps(SCENE_SCHEMA).encode())
        self._ch["/scene"] = self._w.register_channel("/scene", "json", sid)
        self._w.add_metadata(META, {k: str(v) for k, v in meta.items()})
        self._seq = 0
        self.sensors = sensor_positions(meta.get("scenario_text", ""))
        """Sensor name -> (x, y) of the scenario's positioned sensors (the scene's marks)."""
        self._scorer = None
        self.skipped = 0
        """Truth or scene records left out because they could not be made."""

    def attach(self, core: PeerCore) -> None:
        """Also record the truth ``core`` scores against and the scene of each published
        Tracks message (its position index picks x, y from a state)."""
        self._scorer = core.scorer

    def _log(self, topic: str, now: float, record: dict) -> None:
        self._seq += 1
        t = max(0, int(now * 1e9))
        self._w.add_message(self._ch[topic], t, dumps(record).encode(), t,
                            sequence=self._seq)

    def receive(self, now: float, key: str, payload: bytes) -> None:
        self._log("receive", now, {"t": now, "key": key, "payload": _b64(payload),
                                   "message": _decoded(payload)})

    def liveliness(self, now: float, name: str, joined: bool) -> None:
        self._log("liveliness", now, {"t": now, "name": name, "joined": bool(joined)})

    def tick(self, now: float) -> None:
        self._log("tick", now, {"t": now})

    def finish(self, now: float) -> None:
        self._log("finish", now, {"t": now})

    def tracks(self, now: float, k: int, payload: bytes) -> None:
        try:
            msg = decode(bytes(payload))
        except Rejected:
            msg = None
        self._log("tracks", now, {"t": now, "k": int(k), "payload": _b64(payload),
                                  "message": None if msg is None else fields(msg)})
        if self._scorer is None:
            return
        try:
            self._readers(now, int(k), msg)
        except (ValueError, IndexError, TypeError):  # a reader's aid never stops the peer
            self.skipped += 1

    def _readers(self, now: float, k: int, msg) -> None:
        """The truth at scan ``k`` and the scene of the Tracks ``msg`` (None: undecodable)."""
        truth, truth_ids = self._scorer.truth(int(k)), self._scorer.truth_ids(int(k))
        if truth is not None:
            self._log("truth", now, {"t": now, "k": int(k), "states": np.asarray(
                truth, float).tolist(), "ids": None if truth_ids is None else np.asarray(
                truth_ids, np.int64).tolist()})
        if msg is not None:
            scene = scene_update(now, msg.sender, msg.states, tuple(self._scorer.pos),
                                 ids=msg.ids, covs=msg.covs, status=msg.status, truth=truth,
                                 truth_ids=truth_ids, sensors=self.sensors)
            self._log("/scene", now, scene)

    def telemetry(self, now: float, payload: bytes) -> None:
        """A telemetry message the peer made (peers.observer), recorded whether or not a view
        heard it; bounded as the reports are (peers.observer: at most ``POOLED_SHOWN`` pooled,
        ``PARTICLES_SHOWN`` particles and ``FUSED_SHOWN`` marks a mixture, per scan)."""
        if self._fh is not None:
            self._log("telemetry", now, {"t": now, "payload": _b64(payload)})

    def close(self) -> None:
        if self._fh is not None:
            self._w.finish()
            self._fh.close()
            self._fh = None


def _b64(data: bytes) -> str:
    return base64.b64encode(bytes(data)).decode("ascii")


def _decoded(payload: bytes) -> dict | None:
    """Every field of a payload (:func:`protocol.json_fields.fields`), None if it does not
    decode (sealed, forged or garbled bytes are still recorded as bytes)."""
    try:
        return fields(decode(bytes(payload)))
    except Rejected:
        return None


def sensor_positions(scenario_text: str) -> dict[str, tuple[float, float]]:
    """``{name: (x, y)}`` of the ``[[sensors]]`` with a ``position`` in a scenario's TOML
    text (none if it does not parse: the scene is then drawn without sensors)."""
    try:
        doc = tomllib.loads(scenario_text or "")
    except tomllib.TOMLDecodeError:
        return {}
    out = {}
    for s in doc.get("sensors", []):
        pos = s.get("position") if isinstance(s, dict) else None
        if isinstance(pos, list) and len(pos) >= 2 and "name" in s:
            out[str(s["name"])] = (float(pos[0]), float(pos[1]))
    return out


_FIELDS = {"receive": ("t", "key", "payload"), "liveliness": ("t", "name", "joined"),
           "tick": ("t",), "finish": ("t",), "tracks": ("t", "k", "payload"),
           "truth": ("t", "k", "ids", "states"), "telemetry": ("t", "payload")}


def _record(topic: str, encoding: str, data: bytes) -> list:
    """A message as the positional record ``replay`` feeds (JSON, or the msgpack of
    recordings made before the schemas)."""
    if encoding != "json":
        return msgpack.unpackb(data, raw=False)
    body = json.loads(data)
    return [base64.b64decode(body[f]) if f == "payload" else body[f] for f in _FIELDS[topic]]


def read(path: Path, topics: tuple[str, ...] = TOPICS) -> tuple[dict[str, str],
                                                                list[tuple[str, list]]]:
    """The metadata and the records ``(topic, record)`` of a recording, in order, of
    ``topics`` (a replay's by default; ``"truth"`` too for the view's offline picture); a file
    that is not a complete MCAP file is a one-line :class:`ValueError`."""
    # heavy dependency: mcap, as in Recorder
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    with Path(path).open("rb") as fh:
        try:
            reader = make_reader(fh)
            meta = {}
            for m in reader.iter_metadata():
                if m.name == META:
                    meta = dict(m.metadata)
            fh.seek(0)
            reader = make_reader(fh)
            records = [(ch.topic, _record(ch.topic, ch.message_encoding, msg.data))
                       for _, ch, msg in reader.iter_messages(topics=list(topics),
                                                              log_time_order=False)]
        except McapError as exc:
            raise ValueError(
                f"not a complete recording ({type(exc).__name__}): a peer that was "
                f"killed (--fault kill:...) never closed its file, and what it held in its "
                f"last chunk is lost") from None
    return meta, records


@dataclass
class Replay:
    """What a replay produced against what was recorded."""

    peer: str
    tracks: dict[int, np.ndarray] = field(default_factory=dict)
    recorded: dict[int, bytes] = field(default_factory=dict)
    replayed: dict[int, bytes] = field(default_factory=dict)
    snapshot: dict = field(default_factory=dict)

    @property
    def identical(self) -> bool:
        """Every recorded tracks message came out byte for byte (the send time aside)."""
        return bool(self.recorded) and all(
            _states(self.replayed.get(k)) == _states(v) for k, v in self.recorded.items())


def _states(payload: bytes | None) -> bytes | None:
    """The states block of an encoded Tracks message (its send time differs by design)."""
    if payload is None:
        return None
    body = msgpack.unpackb(payload, raw=False)
    return bytes(body[-1])


def replay_with(path: Path, build: Callable[[dict[str, str]], PeerCore]) -> Replay:
    """Feed a recording through the peer ``build(meta)`` makes from its metadata (the caller
    in ``sim`` rebuilds it from the stored scenario: this layer knows no scenario)."""
    meta, records = read(path)
    if not meta:
        raise ValueError(f"{path}: not a sensornet recording (no '{META}' metadata)")
    core = build(meta)
    out = Replay(meta["peer"])
    for topic, r in records:
        if topic == "receive":
            outputs = core.receive(r[1], r[2], r[0], admitted=True)
        elif topic == "liveliness":
            outputs = core.liveliness(r[1], bool(r[2]), r[0])
        elif topic == "tick":
            outputs = core.tick(r[0])
        elif topic == "finish":
            outputs = core.finish(r[0])
        else:
            out.recorded[int(r[1])] = r[2]
            continue
        for o in outputs:
            if isinstance(o, Publish) and o.channel == "tracks":
                out.replayed[o.k] = o.payload
                out.tracks[o.k] = o.message.states
    out.snapshot = core.snapshot()
    return out
