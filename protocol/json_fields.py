"""Every field of a wire message as plain JSON values, for tools outside sensornet.

The wire is positional msgpack with raw float64 blocks (protocol.codec): compact, but opaque to
a generic reader. :func:`fields` turns a decoded message into a JSON object with named fields
(arrays as nested lists, a Gaussian mixture as ``weights``/``means``/``covs``), which recordings
(peers.recording, ``sensornet record``) and ``sensornet echo --json`` write, so ``json.loads``
alone gives every field. :data:`MESSAGE_SCHEMA` is its JSON Schema. Floats go through Python's
``repr``, which round-trips a float64 exactly; NaN and infinities are written as ``null``.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields as dataclass_fields
from typing import Any

import numpy as np
from sensornet.protocol.messages import Message, ScanSet
from sensornet.tracking.mixture import GaussianMixture

KINDS = {"Scan": "scan", "Estimate": "estimate", "Tracks": "tracks", "Truth": "truth",
         "Control": "control", "Forward": "forward", "Returns": "returns",
         "Telemetry": "telemetry"}
"""Message class -> the ``type`` field of its JSON object."""

MESSAGE_SCHEMA: dict = {
    "title": "sensornet.message",
    "description": "A decoded sensornet wire message (protocol.messages): 'type' names it, the "
                   "other properties are its dataclass fields; arrays are nested lists (a "
                   "state row is [px, vx, py, vy] in the seed scenarios), NaN is null.",
    "type": "object",
    "properties": {
        "type": {"type": "string", "enum": sorted(KINDS.values())},
        "sender": {"type": "string"}, "sensor": {"type": "string"},
        "k": {"type": "integer", "description": "scan index (simulated time k T)"},
        "send_time": {"type": "number", "description": "sender's wall clock, s since epoch"},
        "z": {"type": "array", "description": "(m, 2) measurements"},
        "ages": {"type": ["array", "null"],
                 "description": "Scan: (m,) s each plot was made before the scan's time"},
        "states": {"type": "array", "description": "(n, d) target states"},
        "ids": {"type": ["array", "null"],
                "description": "Tracks: (n, 3) labels [origin, birth_scan, index]; Truth: (n,)"},
        "covs": {"type": ["array", "null"], "description": "(n, d, d) state covariances"},
        "existence": {"type": ["array", "null"], "description": "(n,) probabilities"},
        "status": {"type": ["array", "null"], "description": "(n,) 0 tentative, 1 confirmed"},
        "mixture": {"type": ["object", "null"],
                    "description": "Gaussian mixture: weights (n,), means (n, d), covs (n, d, d)"},
        "labels": {"type": ["array", "null"], "description": "(n, 3) component labels"},
        "label_masks": {"type": ["array", "null"],
                        "description": "Estimate: (n, W) holder-mask words 1.. of its labels"},
        "scans": {"type": "object", "description": "Forward: origin sensor -> (m, 2) returns"},
    },
    "required": ["type"],
}


def _plain(value: Any) -> Any:
    """A field value as JSON values (NaN and infinities as None)."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            return np.where(np.isfinite(value), value.astype(object), None).tolist()
        return value.tolist()  # nested lists of Python ints and floats: nothing to walk
    if isinstance(value, GaussianMixture):
        return {"weights": _plain(value.weights), "means": _plain(value.means),
                "covs": _plain(value.covs)}
    if isinstance(value, ScanSet):
        return {origin: _plain(z) for origin, z in value.scans.items()}
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, dict) or hasattr(value, "items"):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def fields(msg: Message) -> dict:
    """``{"type": kind, field: value, ...}``: every dataclass field of ``msg`` as JSON values."""
    out: dict[str, Any] = {"type": KINDS.get(type(msg).__name__, type(msg).__name__.lower())}
    for f in dataclass_fields(msg):
        out[f.name] = _plain(getattr(msg, f.name))
    return out


def dumps(obj: dict) -> str:
    """Compact JSON text of ``obj`` (what the recordings and ``echo --json`` write)."""
    return json.dumps(obj, separators=(",", ":"))
