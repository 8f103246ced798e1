"""``sensornet view``: attach a live Rerun view to a running network (it only subscribes)."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from sensornet.cli.common import UserError
from sensornet.peers.rerun_layout import legend_markdown
from sensornet.peers.rerun_sink import RerunSink, color_of
from sensornet.peers.security import (
    OBSERVER,
    OBSERVER_PREFIX,
    ROUTER_PREFIX,
    WORLD,
    Security,
    SecurityError,
    load_roster,
)
from sensornet.peers.session import SessionError
from sensornet.protocol.keys import check_name
from sensornet.sim.kinds import kind_of
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.view import (
    Batcher,
    LiveView,
    ViewState,
    cpu_seconds,
    idle_process,
    nice_process,
    normal_process,
    replay_recordings,
)
from sensornet.view_map import GeoViewState, geo_map

FOLLOW_RADIUS = 400.0
"""The "around the target" view's half-width (m), as the world drew it."""


def _scenario(args: argparse.Namespace):
    """The scenario the network plays (``--scenario``, ``--set``), or None."""
    if not args.scenario:
        return None
    try:
        scn = load_scenario(args.scenario, overrides=parse_overrides(args.set or []))
    except (OSError, ValueError, KeyError) as exc:
        raise UserError(f"scenario {args.scenario!r}: {exc}") from None
    return scn, kind_of(scn).view.layout()


def cmd_view(args: argparse.Namespace) -> int:
    """Subscribe to NETWORK and build its Rerun recording (``--out``) and/or stream it to a
    viewer (``--viewer``) until Ctrl-C, ``--duration`` or (``--until-end``) the run's end."""
    viewer, out = _check_args(args)
    security = _observer(args)
    if args.from_mcap:  # offline: the peers' recordings instead of the network
        sink, state = _open_sink(args, out, viewer)
        return _replay_offline(args, sink, state, out or viewer)
    scn = _scenario(args) if args.until_end else None  # a run's view: it knows the peers
    view = LiveView(args.network, None, None, None, args.connect or [], args.config,
                    estimates=args.estimates, security=security,
                    discard=getattr(args, "discard", False),
                    peers=scn[0].sensor_names if scn is not None else ())
    cpu = _watch(args, view, out, viewer)
    _print_stats(view, cpu)
    return 0


def _check_args(args: argparse.Namespace) -> tuple[str | None, Path | None]:
    """The network name, somewhere to read from (``--connect`` or ``--from-mcap``), a positive
    ``--duration`` and somewhere to draw to; returns the viewer URL (None: no viewer) and the
    ``.rrd`` path (None: no file)."""
    try:
        check_name(args.network, "network name")
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if not args.connect and not args.from_mcap:
        raise UserError("--connect ENDPOINT: a process of the network to join (the world's "
                        "--listen endpoint, say)")
    if args.duration is not None and not args.duration > 0:
        raise UserError("--duration must be positive")
    if args.count is not None and args.count < 1:
        raise UserError("--count must be at least 1")
    viewer = None if args.viewer in (None, "none") else args.viewer
    out = Path(args.out) if args.out else None
    if out is None and viewer is None:
        raise UserError("nothing to show to: give --out FILE.rrd and/or --viewer")
    return viewer, out


def _observer(args: argparse.Namespace) -> Security | None:
    """``--secure DIR [--as NAME]``: the read-only observer's TLS files and the network's
    policy (every member of the folder's roster a peer but the world, routers and observers);
    only an observer (``view*``), which the access control lets subscribe and not put."""
    if not args.secure:
        if args.member:
            raise UserError("--as needs --secure DIR")
        return None
    member = args.member or OBSERVER
    if not member.startswith(OBSERVER_PREFIX):
        raise UserError(f"--as {member}: a view joins as a read-only observer, a member named "
                        f"'{OBSERVER_PREFIX}...' (sensornet keys makes '{OBSERVER}')")
    try:
        peers = [n for n in load_roster(Path(args.secure)) if n != WORLD
                 and not n.startswith((ROUTER_PREFIX, OBSERVER_PREFIX))]
        return Security.load(args.secure, member, args.network, peers)
    except (SecurityError, OSError, ValueError) as exc:
        raise UserError(str(exc)) from None


def _open_sink(args: argparse.Namespace, out: Path | None,
               viewer: str | None) -> tuple[RerunSink, Callable[[Batcher], ViewState]]:
    """Open the recording with the scenario's peers, region and sensors drawn (if
    ``--scenario``); returns the sink and the factory of the view's state, which styles and
    adds to the legend a peer heard that the scenario does not name."""
    found = _scenario(args)
    peers: list[str] = []
    layout = {"single_target": False, "imm": False}
    sensors, region, period, cutoff, geo = {}, None, 1.0, None, None
    if found is not None:
        scn, layout = found
        layout = {**layout, "single_target": layout["single_target"] or len(scn.targets) == 1}
        peers = list(scn.sensor_names)
        sensors = {s.name: (s.kind, s.position) for s in scn.sensors}
        region, period, cutoff = scn.region, scn.scan_period, scn.metrics.ospa_cutoff
        geo = geo_map(scn)  # a geographic origin: the map view too (sensornet.view_map)
    sink = RerunSink().open(args.run_id or args.network, out, viewer, peers=peers,
                            ospa_cutoff=cutoff, follow_radius=FOLLOW_RADIUS,
                            geo=geo is not None, **layout)
    sink.decorate(peers, region=region, follow_radius=FOLLOW_RADIUS, **layout)
    if sensors:
        sink.time(0, 0.0)
        sink.points("world/sensors", np.array([p for _, p in sensors.values()]),
                    [color_of(i) for i in range(len(sensors))], radius=8.0,
                    labels=list(sensors))
    known = list(peers)

    def new_peer(name: str, i: int) -> None:  # heard, not in the scenario: style and legend
        known.append(name)
        sink.decorate_peer(name, i, layout["imm"])
        rr = sink.rr
        rr.log("legend", rr.TextDocument(legend_markdown(known, layout["single_target"],
                                                         layout["imm"], FOLLOW_RADIUS),
                                         media_type=rr.MediaType.MARKDOWN), static=True)

    def state(batcher):
        if geo is not None:
            return GeoViewState(batcher, peers, period, sensors, layout["single_target"],
                                cutoff, on_new_peer=new_peer, geo=geo)
        return ViewState(batcher, peers, period, sensors, layout["single_target"], cutoff,
                         on_new_peer=new_peer)

    return sink, state


def _replay_offline(args: argparse.Namespace, sink: RerunSink,
                    state: Callable[[Batcher], ViewState], dest) -> int:
    """``--from-mcap``: draw the peers' recordings instead of joining the network, then say
    how many messages were drawn to ``dest``."""
    missing = [p for p in args.from_mcap if not Path(p).is_file()]
    if missing:
        sink.close()
        raise UserError(f"--from-mcap: no such file {missing[0]}")
    offline = state(Batcher(sink.rr, sink.rr))
    try:
        drawn = replay_recordings(offline, [Path(p) for p in args.from_mcap])
    except (ValueError, OSError) as exc:  # not a whole recording, unreadable
        sink.close()
        raise UserError(f"--from-mcap: {exc}") from None
    offline.b.flush()
    sink.close()
    print(f"view: {drawn} recorded messages drawn from {len(args.from_mcap)} recordings "
          f"({offline.rejected} undecodable) -> {dest}", file=sys.stderr)
    return 0


def _watch(args: argparse.Namespace, view: LiveView, out: Path | None,
           viewer: str | None) -> float:
    """Join the network, then open the recording, and draw until Ctrl-C/SIGTERM,
    ``--duration`` or the run's end; returns the CPU seconds the view spent."""

    def on_signal(signum, frame) -> None:
        view.stop.set()

    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, on_signal)
    cpu0 = cpu_seconds()
    try:
        view.open()
    except SessionError as exc:
        raise UserError(str(exc)) from None
    try:
        sink, state = _open_sink(args, out, viewer)
    except BaseException:
        view.close()
        raise
    view.draw_into(state, sink.rr, sink.rr)
    # subscribed and its recording open (lowered from its start, it joined a short run late;
    # lowered before the sink, a view left no CPU on a busy machine never wrote its file)
    _lower_priority(args)
    if args.idle:
        view.at_end = normal_process
    print(f"view: network {args.network} via {', '.join(args.connect)} -> "
          f"{out or ''}{' + ' if out and viewer else ''}{viewer or ''} (Ctrl-C to detach)",
          file=sys.stderr, flush=True)
    try:
        view.run(args.duration, until_end=args.until_end, count=args.count)
    finally:
        view.close()
        sink.close()
    return cpu_seconds() - cpu0


def _lower_priority(args: argparse.Namespace) -> None:
    """``--idle``: every thread in SCHED_IDLE (said in one line, as is a fallback to nice);
    else ``--nice``: every thread's nice value raised by it."""
    if args.idle:
        how, n = idle_process(args.nice or 10)
        print(f"view: {n} threads in SCHED_IDLE (CPU time no peer wants)" if how == "idle" else
              f"view: SCHED_IDLE not permitted here: nice +{args.nice or 10} instead",
              file=sys.stderr, flush=True)
    elif args.nice:
        nice_process(args.nice)


def _print_stats(view: LiveView, cpu: float) -> None:
    """What the view did: its lag behind the peers (median, p99, max), the messages drawn,
    dropped and skipped, the Rerun calls, and its CPU per scan."""
    st, b = view.state, view.batcher
    scans = max(1, st.newest_k)
    lag = sorted(st.lag_ms)
    if lag:
        print(f"view: behind the peers by {lag[len(lag) // 2]:.0f} ms median, "
              f"{lag[min(len(lag) - 1, int(0.99 * len(lag)))]:.0f} ms p99, {lag[-1]:.0f} ms "
              f"at most (tracks published -> drawn)", file=sys.stderr, flush=True)
    print(f"view: {st.handled} messages drawn ({st.rejected} undecodable, {st.skipped} "
          f"later-round estimates not drawn), {view.dropped} "
          f"dropped, {view.skipped} estimates skipped, {b.decimated} map frames decimated; "
          f"{b.calls} send_columns calls for {b.rows_sent} rows; CPU {cpu:.2f} s "
          f"({cpu / scans * 1e3:.1f} ms per scan over {st.newest_k} scans)",
          file=sys.stderr, flush=True)
    if view.discard:
        print(f"view: --discard: {view.discarded} messages dropped unread", file=sys.stderr,
              flush=True)
