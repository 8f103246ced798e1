"""A PDA peer's validation gates reach the live view (issue 38): the peer's telemetry carries
each sensor's gate and weighted returns (:func:`peers.observer.pack_gates`), and the view
draws them as the peers did before they stopped logging to Rerun: the ``gamma`` ellipse about
the predicted measurement and the returns coloured by weight."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from sensornet.peers.core import Publish, Record
from sensornet.peers.observer import RETURNS_SHOWN, Observer, pack_gates, unpack_gate
from sensornet.peers.rerun_sink import color_of
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Telemetry, Tracks
from sensornet.sim.studies.seed003 import network as seed003_net

from sensornet.view import Batcher, ViewState


class _Rec:
    """A recording stream that keeps what it is sent, by entity: (scans, columns)."""

    def __init__(self) -> None:
        self.calls: dict[str, tuple[list[int], list]] = {}

    def send_columns(self, path, indexes, columns):
        self.calls[path] = (indexes[0].as_arrow_array().to_pylist(), list(columns))


def _column(columns: list, what: str) -> list:
    """The rows of the column whose descriptor names ``what`` (positions, strips, colors)."""
    (col,) = [c for c in columns if what in str(c.component_descriptor())]
    return col.as_arrow_array().to_pylist()


@pytest.fixture(scope="module")
def meas_peer():
    """Peer s1 of seed 003 (measurement sharing, two sensors) after 6 scans of the twin."""
    cfg = seed003_net.load(overrides={"scenario.num_scans": 6})
    return seed003_net.twin(cfg, "meas", 1).peers["s1"]


def _telemetry(core, k: int) -> Telemetry:
    """What the peer's observer publishes for scan ``k`` after its last fusion round, through
    the codec."""
    sent: list[bytes] = []
    obs = Observer(core, 1.0).attach(sent.append)
    obs.record(Record("fusion", k, {"n_fused": 1, "round": core.consensus.rounds}))
    obs.published(Publish("tracks", k, b"", Tracks(core.name, k, np.zeros((1, 4)))), 1.0)
    obs.flush(idle=True, force=True)
    (bundle,) = sent  # a peer of its own process: one put, its report in a bundle
    ((_, payload),) = unpack_bundle(bundle).entries
    return decode(payload)


def test_a_pda_peer_sends_its_gates_and_the_view_draws_them(meas_peer):
    view = meas_peer.consensus.hooks.pda_view()
    msg = _telemetry(meas_peer, 6)
    assert {"pda/s1", "pda/s2"} <= set(msg.points) and "detector/D_L" in msg.values
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1", "s2"], scan_period=0.5)
    state.message(msg)
    state.b.flush()
    assert state.rejected == 0
    for sensor, v in view["sensors"].items():
        base = f"peers/s1/pda/{sensor}"
        scans, cols = rec.calls[f"{base}/gate"]
        assert scans == [6]
        (strips,) = _column(cols, "strips")
        (outline,) = strips  # one closed ellipse, back in map coordinates (north up: -y)
        d = np.array(outline, float) * [1.0, -1.0] - v["zhat"]
        mahalanobis = np.einsum("ni,ij,nj->n", d, np.linalg.inv(v["S"]), d)
        np.testing.assert_allclose(mahalanobis, v["gamma"], rtol=1e-4)
        r, g, b = color_of(0)  # the peer's colour, RGBA packed
        assert _column(cols, "colors") == [[(r << 24) | (g << 16) | (b << 8) | 255]]
        scans, cols = rec.calls[f"{base}/returns"]
        (xy,) = _column(cols, "positions")
        w = np.asarray(v["weights"])  # the heaviest RETURNS_SHOWN, in their order
        keep = np.sort(np.argsort(w)[::-1][:RETURNS_SHOWN])
        assert len(xy) == min(len(w), RETURNS_SHOWN) > 0
        np.testing.assert_allclose(np.array(xy) * [1.0, -1.0], v["returns"][keep], rtol=1e-6)
        (colors,) = _column(cols, "colors")
        red = np.array(colors, np.uint32) >> 24  # RGBA packed: red is the top byte
        np.testing.assert_array_equal(red, (255 * np.clip(w[keep], 0, 1)).astype(np.uint8))


def test_gates_round_trip_and_a_malformed_one_is_counted_not_drawn():
    S = np.array([[4.0, 1.0], [1.0, 9.0]])
    view = {"sensors": {"a": {"zhat": np.array([1.0, 2.0]), "S": S, "gamma": 9.21,
                              "returns": np.array([[1.0, 2.5], [3.0, 1.0]]),
                              "weights": np.array([0.7, 0.1])},
                        "b": {"zhat": np.zeros(2), "S": np.eye(2), "gamma": 5.0,
                              "returns": np.zeros((0, 2)), "weights": np.zeros(0)},
                        "c": {"zhat": np.zeros(3), "S": np.eye(3), "gamma": 5.0,
                              "returns": np.zeros((0, 3)), "weights": np.zeros(0)}}}
    packed = pack_gates(view)
    assert set(packed) == {"pda/a", "pda/b"}  # a 3-D measurement has no map gate
    zhat, S2, gamma, returns, weights = unpack_gate(packed["pda/a"])
    np.testing.assert_array_equal(zhat, [1.0, 2.0])
    np.testing.assert_array_equal(S2, S)
    assert gamma == 9.21
    np.testing.assert_array_equal(returns, view["sensors"]["a"]["returns"])
    np.testing.assert_array_equal(weights, [0.7, 0.1])
    assert len(unpack_gate(packed["pda/b"])[3]) == 0
    w = np.linspace(0.0, 0.5, RETURNS_SHOWN + 10)[::-1]  # heaviest first
    many = {"sensors": {"a": {**view["sensors"]["a"], "weights": w,
                              "returns": np.column_stack([w, w])}}}
    _, _, _, returns, weights = unpack_gate(pack_gates(many)["pda/a"])
    np.testing.assert_array_equal(weights, w[:RETURNS_SHOWN])  # the lightest 10 left out
    np.testing.assert_array_equal(returns[:, 0], w[:RETURNS_SHOWN])
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["p"])
    bad = np.vstack([packed["pda/a"], [[0.0, 0.0]]])  # 3 + 2 m + 1 rows
    negative = packed["pda/b"].copy()
    negative[2, 1] = -1.0  # gamma
    state.message(decode(encode(Telemetry("p", 1, points={"pda/a": bad, "pda/b": negative}))))
    state.b.flush()
    assert state.rejected == 2 and not [p for p in rec.calls if "/pda/" in p]


def test_a_one_sensor_pda_peer_names_its_gate_after_itself():
    """Estimate sharing (CI): each peer's PDA filter has one sensor, ``"own"`` in its
    ``pda_view``; the telemetry names it after the peer, as measurement sharing does."""
    cfg = seed003_net.load(overrides={"scenario.num_scans": 4})
    core = seed003_net.twin(cfg, "ci", 1).peers["s2"]
    assert set(core.consensus.hooks.pda_view()["sensors"]) == {"own"}
    msg = _telemetry(core, 4)
    assert "pda/s2" in msg.points and not [p for p in msg.points if p.startswith("pda/own")]
    rec = _Rec()
    state = ViewState(Batcher(rr, rec), ["s1", "s2"])
    state.message(msg)
    state.b.flush()
    assert {"peers/s2/pda/s2/gate", "peers/s2/pda/s2/returns"} <= set(rec.calls)
