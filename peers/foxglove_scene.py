"""A peer's picture as a Foxglove ``foxglove.SceneUpdate`` in JSON, for MCAP recordings.

Foxglove's 3D panel draws a channel whose schema is named ``foxglove.SceneUpdate`` (encoding
``jsonschema``, messages ``json``). One update per published Tracks message: every earlier
entity deleted, then the tracks (a cube and a text label each, named by the track's id), their
position covariance as a 2-sigma ellipse (a closed line strip), the true targets (spheres) and
the sensors (cubes and labels). :data:`SCENE_SCHEMA` is written here from Foxglove's message
reference (the subset of fields used); the ``foxglove-sdk`` package writes only protobuf,
which generic readers cannot decode without its descriptors, so hand-written JSON was chosen.
"""

from __future__ import annotations

import numpy as np

ELLIPSE_POINTS = 33
"""Points of a covariance ellipse's line strip (the first repeated at the end)."""
SIGMAS = 2.0
"""Mahalanobis radius of the drawn ellipse (about 86 % of a 2-D Gaussian's mass)."""


def _obj(title: str, props: dict, required: list[str] | None = None) -> dict:
    return {"title": title, "type": "object", "properties": props,
            "required": list(props) if required is None else required}


_NUM = {"type": "number"}
_VEC3 = _obj("foxglove.Vector3", {"x": _NUM, "y": _NUM, "z": _NUM})
_QUAT = _obj("foxglove.Quaternion", {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM})
_POSE = _obj("foxglove.Pose", {"position": _VEC3, "orientation": _QUAT})
_COLOR = _obj("foxglove.Color", {"r": _NUM, "g": _NUM, "b": _NUM, "a": _NUM})
_TIME = _obj("time", {"sec": {"type": "integer", "minimum": 0},
                      "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}})
_SHAPE = {"pose": _POSE, "size": _VEC3, "color": _COLOR}
_LINE = _obj("foxglove.LinePrimitive", {
    "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
    "pose": _POSE, "thickness": _NUM, "scale_invariant": {"type": "boolean"},
    "points": {"type": "array", "items": _VEC3}, "color": _COLOR,
    "colors": {"type": "array", "items": _COLOR},
    "indices": {"type": "array", "items": {"type": "integer"}}})
_TEXT = _obj("foxglove.TextPrimitive", {
    "pose": _POSE, "billboard": {"type": "boolean"}, "font_size": _NUM,
    "scale_invariant": {"type": "boolean"}, "color": _COLOR, "text": {"type": "string"}})
_KV = _obj("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})
_ENTITY = _obj("foxglove.SceneEntity", {
    "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"},
    "lifetime": _TIME, "frame_locked": {"type": "boolean"},
    "metadata": {"type": "array", "items": _KV},
    "cubes": {"type": "array", "items": _obj("foxglove.CubePrimitive", _SHAPE)},
    "spheres": {"type": "array", "items": _obj("foxglove.SpherePrimitive", _SHAPE)},
    "lines": {"type": "array", "items": _LINE},
    "texts": {"type": "array", "items": _TEXT}},
    required=["timestamp", "frame_id", "id"])
_DELETION = _obj("foxglove.SceneEntityDeletion", {
    "timestamp": _TIME, "type": {"type": "integer", "description": "0 MATCHING_ID, 1 ALL"},
    "id": {"type": "string"}})
SCENE_SCHEMA = {**_obj("foxglove.SceneUpdate", {
    "deletions": {"type": "array", "items": _DELETION},
    "entities": {"type": "array", "items": _ENTITY}}),
    "description": "An update to the entities displayed in a 3D scene (Foxglove's message "
                   "reference; the fields sensornet writes)"}
"""JSON Schema of the scene channel (schema name ``foxglove.SceneUpdate``)."""

FRAME = "map"
"""The scenario's plane (x east, y north, metres)."""
TRACK_COLOR = {"r": 0.12, "g": 0.47, "b": 0.71, "a": 0.9}
TENTATIVE_COLOR = {"r": 0.6, "g": 0.6, "b": 0.6, "a": 0.6}
TRUTH_COLOR = {"r": 0.17, "g": 0.63, "b": 0.17, "a": 0.8}
SENSOR_COLOR = {"r": 0.84, "g": 0.15, "b": 0.16, "a": 1.0}
_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def _stamp(t: float) -> dict:
    ns = max(0, int(round(t * 1e9)))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _pose(x: float, y: float) -> dict:
    return {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": _IDENTITY}


def _size(s: float) -> dict:
    return {"x": s, "y": s, "z": s}


def ellipses(means: np.ndarray, covs: np.ndarray, sigmas: float = SIGMAS,
             points: int = ELLIPSE_POINTS) -> np.ndarray:
    """``(n, points, 2)`` closed outlines of ``sigmas``-sigma ellipses of 2-D Gaussians
    ``means (n, 2)``, ``covs (n, 2, 2)``: ``mean + sigmas L [cos, sin]`` with ``L`` the
    closed-form lower Cholesky factor of each covariance (every point at Mahalanobis distance
    ``sigmas``)."""
    a = np.sqrt(np.maximum(covs[:, 0, 0], 0.0))
    b = np.divide(covs[:, 1, 0], a, out=np.zeros_like(a), where=a > 0)
    c = np.sqrt(np.maximum(covs[:, 1, 1] - b * b, 0.0))
    th = np.linspace(0.0, 2 * np.pi, points)
    u, v = np.cos(th)[None, :], np.sin(th)[None, :]  # (1, points)
    x = means[:, :1] + sigmas * a[:, None] * u
    y = means[:, 1:2] + sigmas * (b[:, None] * u + c[:, None] * v)
    return np.stack([x, y], axis=-1)


def scene_update(t: float, peer: str, states: np.ndarray, position_index: tuple[int, int],
                 ids: np.ndarray | None = None, covs: np.ndarray | None = None,
                 status: np.ndarray | None = None, truth: np.ndarray | None = None,
                 truth_ids: np.ndarray | None = None,
                 sensors: dict[str, tuple[float, float]] | None = None,
                 size: float = 30.0) -> dict:
    """One ``foxglove.SceneUpdate`` (as a dict) of a peer's tracks at time ``t`` (s since the
    epoch): ``states (n, d)`` with optional ``ids (n, 3)``, ``covs (n, d, d)``, ``status (n,)``;
    ``truth (m, d)`` with ``truth_ids (m,)``; ``sensors`` name -> (x, y)."""
    stamp = _stamp(t)
    px, py = position_index
    states = np.asarray(states, float)
    states = states.reshape(len(states), -1) if states.size else np.zeros((0, max(px, py) + 1))
    entities = []
    if len(states):
        xy = states[:, [px, py]]
        loops = None
        if covs is not None and len(covs) == len(states):
            c = np.asarray(covs, float)[:, [px, py]][:, :, [px, py]]
            loops = ellipses(xy, c)
        for i, (x, y) in enumerate(xy.tolist()):
            name = (".".join(str(int(v)) for v in ids[i]) if ids is not None
                    else str(i))
            color = (TENTATIVE_COLOR if status is not None and int(status[i]) == 0
                     else TRACK_COLOR)
            ent = {"timestamp": stamp, "frame_id": FRAME, "id": f"{peer}/track/{name}",
                   "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False,
                   "metadata": [{"key": "peer", "value": peer}, {"key": "track", "value": name}],
                   "cubes": [{"pose": _pose(x, y), "size": _size(size), "color": color}],
                   "texts": [{"pose": _pose(x + size, y + size), "billboard": True,
                              "font_size": 14.0, "scale_invariant": True, "color": color,
                              "text": name}]}
            if loops is not None:
                ent["lines"] = [{"type": 0, "pose": _pose(0.0, 0.0), "thickness": 2.0,
                                 "scale_invariant": True,
                                 "points": [{"x": p[0], "y": p[1], "z": 0.0}
                                            for p in loops[i].tolist()],
                                 "color": color, "colors": [], "indices": []}]
            entities.append(ent)
    if truth is not None and np.asarray(truth).size:
        tr = np.asarray(truth, float).reshape(len(truth), -1)[:, [px, py]]
        for j, (x, y) in enumerate(tr.tolist()):
            tid = str(int(truth_ids[j])) if truth_ids is not None and len(truth_ids) == len(tr) \
                else str(j)
            entities.append({"timestamp": stamp, "frame_id": FRAME, "id": f"truth/{tid}",
                             "metadata": [{"key": "truth", "value": tid}],
                             "spheres": [{"pose": _pose(x, y), "size": _size(size * 0.7),
                                          "color": TRUTH_COLOR}]})
    for name, (x, y) in (sensors or {}).items():
        entities.append({"timestamp": stamp, "frame_id": FRAME, "id": f"sensor/{name}",
                         "metadata": [{"key": "sensor", "value": name}],
                         "cubes": [{"pose": _pose(x, y), "size": _size(size * 1.5),
                                    "color": SENSOR_COLOR}],
                         "texts": [{"pose": _pose(x, y - 2 * size), "billboard": True,
                                    "font_size": 14.0, "scale_invariant": True,
                                    "color": SENSOR_COLOR, "text": name}]})
    return {"deletions": [{"timestamp": stamp, "type": 1, "id": ""}], "entities": entities}
