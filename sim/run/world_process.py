"""The world process: plays a scenario over Zenoh, publishing truth and every sensor's scans.

It waits until the expected peers are ready (a liveliness token a peer declares once it sees
all its neighbours), then publishes scan ``k`` of every sensor every ``scan_period / speed``
seconds and the truth half an interval later (:data:`TRUTH_DELAY`), and a ``Control("end")``
after the last scan's fusion deadline. Truth and scans are logged to the run's Rerun recording
at scan ``k``.
"""

from __future__ import annotations

import signal
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import zenoh
from sensornet.peers.rerun_sink import (
    TRUTH_COLOR,
    RerunSink,
    TruthPaths,
    color_of,
    position_columns,
)
from sensornet.peers.session import ANNOUNCE, PEER_WAIT, open_session
from sensornet.peers.transport import recovering_publisher, zenoh_encoding
from sensornet.protocol.bundle import pack_bundles
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Scan, Truth
from sensornet.sim.kinds import kind_of
from sensornet.sim.scenario import Scenario
from sensornet.sim.world import generate_run

TRUTH_DELAY = 0.5
"""The truth of scan ``k`` is published this fraction of a scan interval after its scans.

Truth is an evaluation side channel (peers score OSPA with it), not an input of the filters:
sent with the scans it costs every peer a message, a decode and a scoring step in the very
burst of work that decides the scan-to-track latency. The world's Rerun logging of the scan
(truth and scans, at scan ``k`` on the timelines) is done then too, for the same reason."""


def _wait_until(stop: threading.Event, when: float) -> None:
    pause = when - time.monotonic()
    if pause > 0:
        stop.wait(pause)


def _publish_truth(pub, truth, k: int) -> None:
    pub.put(encode(Truth(k, truth.ids[k - 1], truth.states[k - 1], send_time=time.time())))


class _Sealed:
    """A publisher whose every message is signed by the world (secure mode)."""

    def __init__(self, pub, key: str, signer) -> None:
        self.pub, self.key, self.signer = pub, key, signer

    def put(self, payload: bytes) -> None:
        self.pub.put(self.signer.seal(self.key, payload),
                     encoding=zenoh_encoding(payload, sealed=True))


class _Typed:
    """A publisher whose every put declares the message's Zenoh encoding (protocol.encodings)."""

    def __init__(self, pub) -> None:
        self.pub = pub

    def put(self, payload: bytes) -> None:
        self.pub.put(payload, encoding=zenoh_encoding(payload))


def _await_subscribers(pubs, stop: threading.Event, timeout: float) -> None:
    """Until every publisher has a matching subscriber, or ``timeout``: through a router a
    peer's subscription can reach the world after the peer's ``ready`` token (under load, the
    first scan was lost without this)."""
    end = time.monotonic() + timeout
    while not stop.is_set() and time.monotonic() < end:
        if all(getattr(p, "pub", p).matching_status.matching for p in pubs):
            return
        stop.wait(0.01)


FOLLOW_RADIUS = 400.0
"""Half-width (m) of the "around the target" view of single-target scenarios."""


class WorldError(Exception):
    """The world could not start the run (reported in one line)."""


def run_world(scn: Scenario, network: str, run: int = 0, listen=(), connect=(),
              config_file: str | None = None, wait_for: list[str] | None = None,
              wait_timeout: float = PEER_WAIT, out_dir: Path | None = None,
              run_id: str | None = None, viewer: str | None = None,
              speed: float | None = None, progress=None, rerun: bool = True,
              say=None, security=None, data=None, recover: bool = False,
              bundles: dict[str, list[str]] | None = None) -> dict:
    """Play run ``run`` of the scenario; returns what was published.

    ``data``: the run's ``(truth, scans)`` (default :func:`sim.world.generate_run`'s).

    ``progress(k)`` is called after scan ``k`` is published; ``say(line)`` gets the status
    lines (waiting for the peers, starting). ``recover``: scans through Zenoh's advanced
    publisher (:func:`peers.transport.recovering_publisher`), so a peer that missed some (a
    router's outage) gets them from the world's cache. ``bundles``: peer host -> its sensors,
    whose scans go to the host in one message per scan (:mod:`protocol.bundle`) instead of
    one per sensor (plain mode only: not with ``security`` or ``recover``).
    """
    if bundles and (security is not None or recover):
        raise WorldError("scan bundles are for plain runs (no --secure, no --recover)")
    bundles = {h: list(ss) for h, ss in (bundles or {}).items()}
    unknown = sorted({s for ss in bundles.values() for s in ss} - set(scn.sensor_names))
    if unknown:
        raise WorldError(f"--bundle names unknown sensors {unknown}")
    bundled = {s for ss in bundles.values() for s in ss}
    named = Counter(s for ss in bundles.values() for s in ss)
    twice = sorted(s for s, n in named.items() if n > 1)
    if twice:
        raise WorldError(f"--bundle names sensors {twice} more than once (a sensor's scans go "
                         "to one host)")
    say = say or (lambda line: None)
    keys = Keys(network)
    speed = speed or scn.network.speed
    interval = scn.scan_period / speed
    truth, scans = data if data is not None else generate_run(scn, run)
    stop = threading.Event()

    def on_signal(signum, frame):
        stop.set()

    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, on_signal)
    sink = RerunSink()
    view = kind_of(scn).view  # the peer kind's Rerun layout (sim/kinds)
    layout = {**view.layout(), "follow_radius": FOLLOW_RADIUS}
    layout["single_target"] = layout["single_target"] or len(scn.targets) == 1
    if out_dir is not None and rerun or viewer:
        sink.open(run_id or network, out_dir / "rerun" / "world.rrd" if out_dir and rerun
                  else None,
                  viewer, peers=scn.sensor_names, ospa_cutoff=scn.metrics.ospa_cutoff,
                  **layout)
        sink.decorate(scn.sensor_names, region=scn.region, **layout)
    signer = security.signer() if security is not None else None  # before any socket
    # peers dial the world (every one has its endpoint): it dials nobody it hears of by
    # gossip, so each of its links is dialled again by the peer that made it (ANNOUNCE)
    session = open_session(listen, connect, config_file, gossip=ANNOUNCE, security=security)
    alive: set[str] = set()
    cond = threading.Condition()

    def on_live(sample):
        with cond:
            name = Keys.last(str(sample.key_expr))
            if sample.kind == zenoh.SampleKind.PUT:
                alive.add(name)
            else:
                alive.discard(name)
            cond.notify_all()

    sent = {"scans": 0, "bytes": 0, "scans_published": 0, "bundles": 0}
    ros2 = None
    try:
        live_sub = session.liveliness().declare_subscriber(keys.ready("*"), on_live,
                                                           history=True)
        block = zenoh.CongestionControl.BLOCK
        pubs = {n: session.declare_publisher(keys.scan(n), congestion_control=block,
                                              express=True)
                for n in scn.sensor_names}
        probes = pubs  # matching_status: an advanced publisher has none, a plain one does
        if recover:
            pubs = {n: recovering_publisher(session, keys.scan(n)) for n in scn.sensor_names}
        bundle_pubs = {h: session.declare_publisher(keys.scans(h), congestion_control=block,
                                                    express=True) for h in bundles}
        truth_pub = session.declare_publisher(keys.truth(), congestion_control=block,
                                        express=True)
        ctl_pub = session.declare_publisher(keys.ctl(), congestion_control=block)
        if signer is not None:  # scans, truth and control, signed (protocol.envelope)
            pubs = {n: _Sealed(p, keys.scan(n), signer) for n, p in pubs.items()}
            truth_pub = _Sealed(truth_pub, keys.truth(), signer)
            ctl_pub = _Sealed(ctl_pub, keys.ctl(), signer)
        else:
            pubs = {n: _Typed(p) for n, p in pubs.items()}
            truth_pub, ctl_pub = _Typed(truth_pub), _Typed(ctl_pub)
        token = session.liveliness().declare_token(keys.alive("world"))
        if scn.network.ros2:  # each sensor's detections as ROS 2 point clouds (docs/ros2.md)
            try:
                from sensornet.peers.ros2 import WorldRos2  # optional dependency: rosbags
            except ImportError:
                raise WorldError("network.ros2 (--ros2) needs rosbags: pip install "
                                 "'sensornet[ros2]'") from None
            ros2 = WorldRos2(session, scn.sensor_names, scn.network.ros2_domain)
        if wait_for:
            say(f"world: waiting up to {wait_timeout:g} s for peers {', '.join(wait_for)}")
            deadline = time.monotonic() + wait_timeout
            with cond:
                while not set(wait_for) <= alive:
                    left = deadline - time.monotonic()
                    if left <= 0 or stop.is_set():
                        missing = sorted(set(wait_for) - alive)
                        if stop.is_set():  # Ctrl-C / SIGTERM, not a timeout
                            raise WorldError(f"interrupted while waiting for peers {missing} "
                                             f"to come up")
                        raise WorldError(f"peers {missing} did not come up within "
                                         f"{wait_timeout:g} s")
                    cond.wait(timeout=min(left, 0.2))
            time.sleep(0.2)  # let the peers' subscriptions settle on every link
            _await_subscribers([*(probes[n] for n in wait_for if n in probes),
                                *bundle_pubs.values()], stop, 5.0)
        say(f"world: starting {scn.num_scans} scans, one every {interval:g} s")
        ctl_pub.put(encode(Control("start", run_id or network, {"speed": speed},
                                   send_time=time.time())))
        sensors = scn.sensors
        sink.time(0, 0.0)
        sink.points("world/sensors", np.array([s.position for s in sensors]),
                    [color_of(i) for i in range(len(sensors))], radius=8.0,
                    labels=[s.name for s in sensors])
        start = time.monotonic()

        def after_burst(k: int) -> None:
            """Truth message and Rerun logging of scan ``k``, off the peers' busiest moment."""
            _publish_truth(truth_pub, truth, k)
            X = truth.states[k - 1]
            sink.time(k, k * scn.scan_period)
            xy = X[:, position_columns(X.shape[1])]
            sink.points("world/truth", xy, TRUTH_COLOR, radius=6.0,
                        labels=[str(i) for i in truth.ids[k - 1]])
            paths.add(truth.ids[k - 1], xy)
            sink.strips("world/truth/paths", paths.strips(), TRUTH_COLOR)
            sink.scalar("metrics/cardinality/truth", len(X))
            sink.scalar("metrics/ospa/cutoff", scn.metrics.ospa_cutoff)
            if layout["single_target"] and len(xy):
                sink.follow(xy[0])
            for i, s in enumerate(sensors):
                z = scans[i][k - 1]
                if s.kind == "range-bearing" and len(z):  # shown where they point
                    z = np.asarray(s.position) + z[:, :1] * np.column_stack(
                        [np.cos(z[:, 1]), np.sin(z[:, 1])])
                sink.points(f"world/scans/{s.name}", z, color_of(i), radius=2.0)
                if ros2 is not None:
                    ros2.detections(s.name, z, time.time())

        paths = TruthPaths()
        pending = None  # (k, time): scan k's truth and logging, TRUTH_DELAY after its scans
        for k in range(1, scn.num_scans + 1):
            if stop.is_set():
                break
            due = start + (k - 1) * interval
            if pending is not None:
                _wait_until(stop, pending[1])
                after_burst(pending[0])
            _wait_until(stop, due)
            parts = {}
            for i, s in enumerate(sensors):
                z = scans[i][k - 1]
                data = encode(Scan(s.name, k, z, seq=k, send_time=time.time()))
                if s.name in bundled:
                    parts[s.name] = data
                else:
                    pubs[s.name].put(data)
                sent["scans"] += 1
                sent["bytes"] += len(data)
            for h, members in bundles.items():
                for b in pack_bundles(k, [(m, parts[m]) for m in members]):
                    bundle_pubs[h].put(b, encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM)
                    sent["bundles"] += 1
            pending = (k, due + TRUTH_DELAY * interval)
            sent["scans_published"] = k
            if progress is not None:
                progress(k)
        if pending is not None and not stop.is_set():
            _wait_until(stop, pending[1])
            after_burst(pending[0])
        if not stop.is_set():
            stop.wait(scn.network.deadline * interval + 0.1)
        ctl_pub.put(encode(Control("end", run_id or network,  # its last scan: peers score
                                   {"last_k": sent["scans_published"]},  # what they missed
                                   send_time=time.time())))
        time.sleep(0.2)
        token.undeclare()
        live_sub.undeclare()
    finally:
        if ros2 is not None:
            ros2.close()
        session.close()
        sink.close()
    return sent
