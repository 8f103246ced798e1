"""The world process: plays a scenario over Zenoh, publishing truth and every sensor's scans.

It waits until the expected peers are ready (a liveliness token a peer declares once it sees
all its neighbours), then publishes scan ``k`` of every sensor every ``scan_period / speed``
seconds and the truth half an interval later (:data:`TRUTH_DELAY`), and a ``Control("end")``
after the last scan's fusion deadline. Truth and scans are logged to the run's Rerun recording
at scan ``k``.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
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
from sensornet.sim.run.run_handle import WORLD_STARTED
from sensornet.sim.scenario import Scenario
from sensornet.sim.world import generate_run, plot_ages

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
              bundles: dict[str, list[str]] | None = None, view_wait: float = 0.0) -> dict:
    """Play run ``run`` of the scenario; returns what was published.

    ``data``: the run's ``(truth, scans)`` (default :func:`sim.world.generate_run`'s).

    ``progress(k)`` is called after scan ``k`` is published; ``say(line)`` gets the status
    lines (waiting for the peers, starting). ``recover``: scans through Zenoh's advanced
    publisher (:func:`peers.transport.recovering_publisher`), so a peer that missed some (a
    router's outage) gets them from the world's cache. ``bundles``: peer host -> its sensors,
    whose scans go to the host in one message per scan (:mod:`protocol.bundle`) instead of
    one per sensor (plain mode only: not with ``security`` or ``recover``). ``view_wait``:
    seconds from the start that the first scan waits at most for a subscriber on the truth
    (the run's view, :data:`sim.run.run_handle.VIEW_WAIT`); 0, the default: no wait.
    """
    bundles = _checked_bundles(scn, bundles, security, recover)
    speed = speed or scn.network.speed
    truth, scans = data if data is not None else generate_run(scn, run)
    world = _World(scn=scn, keys=Keys(network), name=run_id or network, speed=speed,
                   truth=truth, scans=scans, ages=plot_ages(scn, run), bundles=bundles,
                   say=say or (lambda line: None), progress=progress)
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, world.on_signal)
    world.open_sink(out_dir, rerun, viewer)
    signer = security.signer() if security is not None else None  # before any socket
    # peers dial the world (every one has its endpoint): it dials nobody it hears of by
    # gossip, so each of its links is dialled again by the peer that made it (ANNOUNCE)
    session = open_session(listen, connect, config_file, gossip=ANNOUNCE, security=security)
    try:
        world.declare(session, signer, recover)
        declared = time.monotonic()
        if wait_for:
            world.wait_for_peers(wait_for, wait_timeout)
        if view_wait > 0:
            world.wait_for_view(declared + view_wait, view_wait)
        world.play()
        world.end()
    finally:
        if world.ros2 is not None:
            world.ros2.close()
        session.close()
        world.sink.close()
    return world.sent


def _checked_bundles(scn: Scenario, bundles: dict[str, list[str]] | None, security,
                     recover: bool) -> dict[str, list[str]]:
    """``bundles`` as host -> its sensors, checked: plain runs only, known sensors, each
    sensor's scans to one host (:class:`WorldError` otherwise)."""
    if bundles and (security is not None or recover):
        raise WorldError("scan bundles are for plain runs (no --secure, no --recover)")
    bundles = {h: list(ss) for h, ss in (bundles or {}).items()}
    unknown = sorted({s for ss in bundles.values() for s in ss} - set(scn.sensor_names))
    if unknown:
        raise WorldError(f"--bundle names unknown sensors {unknown}")
    named = Counter(s for ss in bundles.values() for s in ss)
    twice = sorted(s for s, n in named.items() if n > 1)
    if twice:
        raise WorldError(f"--bundle names sensors {twice} more than once (a sensor's scans go "
                         "to one host)")
    return bundles


@dataclass
class _World:
    """The state of one :func:`run_world`, with a method per phase: open the recording,
    declare the publishers, wait for the peers, play the scans, end the run."""

    scn: Scenario
    keys: Keys
    name: str
    """The run's id in control messages and the recording (``run_id``, else the network)."""
    speed: float
    truth: object
    scans: list
    """``scans[i][k - 1]``: sensor ``i``'s measurements ``(m, 2)`` at scan ``k``."""
    ages: list | None
    """``ages[i][k - 1]``: their plots' ages (:func:`sim.world.plot_ages`), or None."""
    bundles: dict[str, list[str]]
    say: Callable[[str], None]
    progress: Callable[[int], None] | None
    stop: threading.Event = field(default_factory=threading.Event)
    sink: RerunSink = field(default_factory=RerunSink)
    alive: set[str] = field(default_factory=set)
    """The peers whose ``ready`` token is up."""
    cond: threading.Condition = field(default_factory=threading.Condition)
    sent: dict = field(default_factory=lambda: {"scans": 0, "bytes": 0, "scans_published": 0,
                                                "bundles": 0})
    ros2: object = None
    paths: TruthPaths = field(default_factory=TruthPaths)

    def __post_init__(self) -> None:
        self.interval = self.scn.scan_period / self.speed
        self.bundled = {s for ss in self.bundles.values() for s in ss}
        view = kind_of(self.scn).view  # the peer kind's Rerun layout (sim/kinds)
        self.layout = {**view.layout(), "follow_radius": FOLLOW_RADIUS}
        self.layout["single_target"] = (self.layout["single_target"]
                                        or len(self.scn.targets) == 1)

    def on_signal(self, signum, frame) -> None:
        self.stop.set()

    def open_sink(self, out_dir: Path | None, rerun: bool, viewer: str | None) -> None:
        """The world's Rerun recording (``<out>/rerun/world.rrd``) and/or live viewer, with the
        sensors and region drawn; nothing without either."""
        scn = self.scn
        if out_dir is not None and rerun or viewer:
            self.sink.open(self.name, out_dir / "rerun" / "world.rrd" if out_dir and rerun
                           else None,
                           viewer, peers=scn.sensor_names, ospa_cutoff=scn.metrics.ospa_cutoff,
                           **self.layout)
            self.sink.decorate(scn.sensor_names, region=scn.region, **self.layout)

    def on_live(self, sample) -> None:
        """A peer's ``ready`` token came or went."""
        with self.cond:
            name = Keys.last(str(sample.key_expr))
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(name)
            else:
                self.alive.discard(name)
            self.cond.notify_all()

    def declare(self, session, signer, recover: bool) -> None:
        """The liveliness subscriber, every publisher (scans, bundles, truth, control; signed
        with ``signer`` in secure mode, typed otherwise), the world's token and ROS 2 output."""
        keys, names = self.keys, self.scn.sensor_names
        self.live_sub = session.liveliness().declare_subscriber(keys.ready("*"), self.on_live,
                                                                history=True)
        block = zenoh.CongestionControl.BLOCK
        pubs = {n: session.declare_publisher(keys.scan(n), congestion_control=block,
                                              express=True) for n in names}
        self.probes = pubs  # matching_status: an advanced publisher has none, a plain one does
        if recover:
            pubs = {n: recovering_publisher(session, keys.scan(n)) for n in names}
        self.bundle_pubs = {h: session.declare_publisher(keys.scans(h), congestion_control=block,
                                                         express=True) for h in self.bundles}
        truth_pub = session.declare_publisher(keys.truth(), congestion_control=block,
                                              express=True)
        ctl_pub = session.declare_publisher(keys.ctl(), congestion_control=block)
        if signer is not None:  # scans, truth and control, signed (protocol.envelope)
            self.pubs = {n: _Sealed(p, keys.scan(n), signer) for n, p in pubs.items()}
            self.truth_pub = _Sealed(truth_pub, keys.truth(), signer)
            self.ctl_pub = _Sealed(ctl_pub, keys.ctl(), signer)
        else:
            self.pubs = {n: _Typed(p) for n, p in pubs.items()}
            self.truth_pub, self.ctl_pub = _Typed(truth_pub), _Typed(ctl_pub)
        self.token = session.liveliness().declare_token(keys.alive("world"))
        if self.scn.network.ros2:  # each sensor's detections as ROS 2 point clouds (docs/ros2.md)
            try:
                from sensornet.peers.ros2 import WorldRos2  # optional dependency: rosbags
            except ImportError:
                raise WorldError("network.ros2 (--ros2) needs rosbags: pip install "
                                 "'sensornet[ros2]'") from None
            self.ros2 = WorldRos2(session, names, self.scn.network.ros2_domain)

    def wait_for_peers(self, wait_for: list[str], wait_timeout: float) -> None:
        """Until every peer of ``wait_for`` is ready and subscribed (:class:`WorldError` on a
        timeout or a signal)."""
        self.say(f"world: waiting up to {wait_timeout:g} s for peers {', '.join(wait_for)}")
        deadline = time.monotonic() + wait_timeout
        with self.cond:
            while not set(wait_for) <= self.alive:
                left = deadline - time.monotonic()
                if left <= 0 or self.stop.is_set():
                    missing = sorted(set(wait_for) - self.alive)
                    if self.stop.is_set():  # Ctrl-C / SIGTERM, not a timeout
                        raise WorldError(f"interrupted while waiting for peers {missing} "
                                         f"to come up")
                    raise WorldError(f"peers {missing} did not come up within "
                                     f"{wait_timeout:g} s")
                self.cond.wait(timeout=min(left, 0.2))
        time.sleep(0.2)  # let the peers' subscriptions settle on every link
        _await_subscribers([*(self.probes[n] for n in wait_for if n in self.probes),
                            *self.bundle_pubs.values()], self.stop, 5.0)

    def wait_for_view(self, deadline: float, view_wait: float) -> None:
        """Until the truth has a subscriber (the run's view, ``--view-wait``) or ``deadline``
        (monotonic); giving up is one line on stderr, and the run goes on without it."""
        probe = getattr(self.truth_pub, "pub", self.truth_pub)
        if probe.matching_status.matching:
            return
        t0 = time.monotonic()
        self.say(f"world: waiting up to {max(0.0, deadline - t0):.1f} s for the view")
        _await_subscribers([probe], self.stop, deadline - t0)
        if probe.matching_status.matching:
            self.say(f"world: the view subscribed after {time.monotonic() - t0:.1f} s")
        elif not self.stop.is_set():
            print(f"world: no view subscribed within {view_wait:g} s of the start: starting "
                  f"without it (its recording misses the first scans)", file=sys.stderr,
                  flush=True)

    def play(self) -> None:
        """The start message, then scan ``k`` of every sensor at ``(k - 1)`` intervals, each
        scan's truth and logging :data:`TRUTH_DELAY` of an interval later."""
        scn, sink = self.scn, self.sink
        self.say(f"{WORLD_STARTED}{scn.num_scans} scans, one every {self.interval:g} s")
        self.ctl_pub.put(encode(Control("start", self.name, {"speed": self.speed},
                                        send_time=time.time())))
        sink.time(0, 0.0)
        sink.points("world/sensors", np.array([s.position for s in scn.sensors]),
                    [color_of(i) for i in range(len(scn.sensors))], radius=8.0,
                    labels=[s.name for s in scn.sensors])
        start = time.monotonic()
        pending = None  # (k, time): scan k's truth and logging, TRUTH_DELAY after its scans
        for k in range(1, scn.num_scans + 1):
            if self.stop.is_set():
                break
            due = start + (k - 1) * self.interval
            if pending is not None:
                _wait_until(self.stop, pending[1])
                self.after_burst(pending[0])
            _wait_until(self.stop, due)
            self.publish_scans(k)
            pending = (k, due + TRUTH_DELAY * self.interval)
            self.sent["scans_published"] = k
            if self.progress is not None:
                self.progress(k)
        if pending is not None and not self.stop.is_set():
            _wait_until(self.stop, pending[1])
            self.after_burst(pending[0])

    def publish_scans(self, k: int) -> None:
        """Scan ``k`` of every sensor: one message each, or in its host's bundles."""
        parts = {}
        for i, s in enumerate(self.scn.sensors):
            z = self.scans[i][k - 1]
            a = None if self.ages is None else self.ages[i][k - 1]
            data = encode(Scan(s.name, k, z, seq=k, send_time=time.time(), ages=a))
            if s.name in self.bundled:
                parts[s.name] = data
            else:
                self.pubs[s.name].put(data)
            self.sent["scans"] += 1
            self.sent["bytes"] += len(data)
        for h, members in self.bundles.items():
            for b in pack_bundles(k, [(m, parts[m]) for m in members]):
                self.bundle_pubs[h].put(b, encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM)
                self.sent["bundles"] += 1

    def after_burst(self, k: int) -> None:
        """Truth message and Rerun logging of scan ``k``, off the peers' busiest moment."""
        scn, sink, truth = self.scn, self.sink, self.truth
        _publish_truth(self.truth_pub, truth, k)
        X = truth.states[k - 1]
        sink.time(k, k * scn.scan_period)
        xy = X[:, position_columns(X.shape[1])]
        sink.points("world/truth", xy, TRUTH_COLOR, radius=6.0,
                    labels=[str(i) for i in truth.ids[k - 1]])
        self.paths.add(truth.ids[k - 1], xy)
        sink.strips("world/truth/paths", self.paths.strips(), TRUTH_COLOR)
        sink.scalar("metrics/cardinality/truth", len(X))
        sink.scalar("metrics/ospa/cutoff", scn.metrics.ospa_cutoff)
        if self.layout["single_target"] and len(xy):
            sink.follow(xy[0])
        for i, s in enumerate(scn.sensors):
            z = self.scans[i][k - 1]
            if s.kind == "range-bearing" and len(z):  # shown where they point
                z = np.asarray(s.position) + z[:, :1] * np.column_stack(
                    [np.cos(z[:, 1]), np.sin(z[:, 1])])
            sink.points(f"world/scans/{s.name}", z, color_of(i), radius=2.0)
            if self.ros2 is not None:
                self.ros2.detections(s.name, z, time.time())

    def end(self) -> None:
        """After the last scan's fusion deadline: the "end" message with the last scan
        published (peers score what they missed), then the world leaves."""
        if not self.stop.is_set():
            self.stop.wait(self.scn.network.deadline * self.interval + 0.1)
        self.ctl_pub.put(encode(Control("end", self.name,  # its last scan: peers score
                                        {"last_k": self.sent["scans_published"]},  # missed
                                        send_time=time.time())))
        time.sleep(0.2)
        self.token.undeclare()
        self.live_sub.undeclare()
