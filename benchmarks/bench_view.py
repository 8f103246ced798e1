"""Can one view process show 50 or 100 peers at 10 scans/s? (issue 38)

Feeds the live view's drawing (:class:`sensornet.view.ViewState`, decoding included, into a
real ``.rrd``: Rerun FileSink) what a view hears from a network, and prints its process CPU
per scan against the 100 ms a scan lasts at 10 scans/s. Two sources:

- ``--source twin`` (default): the traffic of the 50-peer network (degree 4, L = 2, 10
  scans/s, the peers packed in ``--hosts`` hosts as ``sensornet run`` packs them), made on
  the twin with every peer watched (``bench_watched.watched_twin``): the world's scan bundles
  and truth, the hosts' report bundles with each scan's tracks, in virtual time order,
  flushed every second of it (:data:`sensornet.view.FLUSH_S`). ``--profile N``: the N
  functions with the most own time. ``--cache FILE``: the traffic kept in FILE (made once).
- ``--source synthetic``: messages of a GM-PHD network's sizes (tracks, round-0 and round-1
  estimates, telemetry, scans, truth), batched logging against one ``rr.log`` per row (what
  the peers did before) and their ratio.

    python benchmarks/bench_view.py                          # twin traffic, 50 peers
    python benchmarks/bench_view.py --peers 100 --scans 60 --cache /tmp/v100.pkl
    python benchmarks/bench_view.py --source synthetic --peers 100 --scans 80
    python benchmarks/bench_view.py --series-every 1,4 --repeats 3   # series every 1 s or 4 s
    python benchmarks/bench_view.py --against c578138 --handling  # + decoding and rows alone
    python benchmarks/bench_view.py --against c578138 --same      # the same .rrd rows?

``--series-every N,M``: only the real-time replay through the view's loop, with the health
series sent once N, then M, :data:`sensornet.view.FLUSH_S` periods of flushes have passed
(:data:`sensornet.view.SERIES_EVERY`: at a 1 s flush period every N-th flush; since 967728f
counted in seconds, not flushes), interleaved ``--repeats`` times: the view's CPU per scan and
how late it handled messages.
"""

from __future__ import annotations

import argparse
import cProfile
import inspect
import os
import pickle
import pstats
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import types
from pathlib import Path

import numpy as np
import rerun as rr

if not __package__:  # `python benchmarks/bench_view.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.rerun_sink import north_up
from sensornet.protocol.bundle import pack_bundles
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Scan, Telemetry, Tracks, Truth
from sensornet.sim.run.twin import world_events
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world import generate_run
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.mixture import GaussianMixture

import sensornet.view as view_module
from benchmarks.bench_watched import watched_twin
from sensornet.view import FLUSH_S, Batcher, LiveView, ViewState
from sensornet.view_columns import ellipse_strips


def _mix(rng: np.random.Generator, n: int) -> GaussianMixture:
    means = rng.uniform(-1000, 1000, size=(n, 4))
    covs = np.tile(np.diag([100.0, 10.0, 100.0, 10.0]), (n, 1, 1))
    return GaussianMixture.trusted(rng.uniform(0.1, 1.0, n), means, covs)


def messages(peers: int, scans: int, rng: np.random.Generator) -> list[list[tuple[str, bytes]]]:
    """Per scan: ``(key, payload)`` of everything the view hears."""
    names = [f"p{i:03d}" for i in range(peers)]
    out = []
    for k in range(1, scans + 1):
        now = time.time()
        batch = [("sensornet/b/truth", encode(Truth(k, np.arange(5), rng.normal(size=(5, 4)),
                                                    send_time=now)))]
        for n in names:
            values = {f"out_of_sequence/{w}": 0.0 for w in ("late", "redundant", "too_old")}
            values.update({"latency_ms": 20.0, "age": 0.0, "components/fused": 10.0,
                           "components/before_level2": 30.0, "components/after_level2": 20.0,
                           "cardinality/local": 5.0, "compute_ms/filter": 1.0,
                           "compute_ms/fusion": 0.5, "ospa/local": 10.0, "ospa/fused": 5.0,
                           **{f"cost/{c}": 100.0 for c in ("tuples", "bytes", "tuples_pub")},
                           **{f"trust/q{j}/{w}": 1.0 for j in range(2)
                              for w in ("statistic", "weight")}})
            batch += [
                (f"sensornet/b/scan/{n}", encode(Scan(n, k, rng.normal(size=(20, 2))))),
                (f"sensornet/b/estimate/{n}", encode(Estimate(n, k, _mix(rng, 20)))),
                (f"sensornet/b/estimate/{n}", encode(Estimate(n, k, _mix(rng, 20), round=1))),
                (f"sensornet/b/tracks/{n}", encode(Tracks(n, k, rng.normal(size=(5, 4)),
                                                          send_time=now))),
                (f"sensornet/b/telemetry/{n}", encode(Telemetry(n, k, values,
                                                                mixture=_mix(rng, 10)))),
            ]
        out.append(batch)
    return out


def twin_traffic(peers: int, scans: int, hosts: int, degree: int = 4,
                 rounds: int = 2) -> tuple[list[str], float, list[tuple[float, str, bytes]]]:
    """What a view hears from ``peers`` peers (degree, rounds, 10 scans/s) in ``hosts``
    hosts, made on the twin: the peers' names, the scan period (s) and the ``(t, key,
    payload)`` heard, in time order (``t``: seconds of the run)."""
    with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
        path = Path(tmp) / "view.toml"
        path.write_text(network_scenario(peers, degree, scans, rounds, speed=10.0))
        scn = load_scenario(str(path))
    names = scn.sensor_names
    heard: list[tuple[float, str, bytes]] = []
    watched_twin(scn, 0, hosts, lambda t, key, payload: heard.append((t, key, payload)))
    keys = Keys("twin")
    truth, scans_ = generate_run(scn, 0)
    interval = scn.scan_period / scn.network.speed
    host_of = {n: f"h{i % hosts + 1}" for i, n in enumerate(names)} if hosts else {}
    world: dict[tuple[float, str], list] = {}
    truths: set[bytes] = set()
    for t, kind, target, *payload in world_events(scn, truth, scans_, keys, interval, (), ()):
        if kind != "msg" or payload[0] == keys.ctl():
            continue
        if payload[0] == keys.truth():  # once, not once per peer
            if payload[1] not in truths:
                truths.add(payload[1])
                heard.append((t, payload[0], payload[1]))
        elif hosts:  # the world's scan bundle of each host
            world.setdefault((t, host_of[target]), []).append((target, payload[1]))
        else:
            heard.append((t, payload[0], payload[1]))
    for (t, host), entries in world.items():
        k = round(t / interval)
        heard += [(t, keys.scans(host), b) for b in pack_bundles(k, entries)]
    heard.sort(key=lambda h: h[0])  # stable: a peer's puts in their order
    return list(names), scn.scan_period, heard


def by_second(heard: list[tuple[float, str, bytes]]) -> list[list[tuple[str, bytes]]]:
    """``(key, payload)`` per :data:`FLUSH_S` of the run (a flush's worth)."""
    seconds: list[list[tuple[str, bytes]]] = []
    for t, key, payload in heard:
        i = int(t / FLUSH_S)
        while len(seconds) <= i:
            seconds.append([])
        seconds[i].append((key, payload))
    return seconds


def realtime(names: list[str], period: float, heard: list[tuple[float, str, bytes]],
             out: Path, kinds: tuple = (Batcher, ViewState, LiveView), skip: float = 2.0) -> dict:
    """The traffic replayed at its pace into the view process's loop (:class:`LiveView`: its
    queue, drain, flushes that lengthen while they are long, decimation), this thread
    feeding the queue: the process CPU per scan after the first ``skip`` seconds, how late
    the view handled what it heard (ms after it was due: median, p99, max), its flush period
    at the end and what it left out (``kinds``: the ``(Batcher, ViewState, LiveView)``
    classes, the loop's too)."""
    rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view-realtime")
    rec.set_sinks(rr.FileSink(str(out)))
    view = (kinds[2] if len(kinds) > 2 else LiveView)("twin", None, rr, rec,
                                                      say=lambda s: None)
    view.rr, view.rec, view.batcher = rr, rec, kinds[0](rr, rec)
    view.state = kinds[1](view.batcher, names, period)
    params = inspect.signature(view.batcher.flush).parameters
    if "between" not in params:  # an older one: its flushes whole, as its view did
        flush = view.batcher.flush
        view.batcher.flush = lambda between=None, every=0, hold=(): flush()
    elif "hold" not in params:  # one that sent its series every flush, as its view did
        flush = view.batcher.flush
        view.batcher.flush = lambda between=None, every=200, hold=(): flush(between, every)
    due: dict[int, float] = {}
    late: list[float] = []
    take = view._take

    def taken(key: str, payload: bytes) -> int:
        late.append(time.monotonic() - due.pop(id(payload)))
        return take(key, payload)

    view._take = taken
    runner = threading.Thread(target=view.run, kwargs={"until_end": True, "grace": 1.0})
    cpu0 = None
    start = time.monotonic() + 0.2
    runner.start()
    for t, key, payload in heard:
        wait = start + t - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        if cpu0 is None and t >= skip:
            cpu0 = time.process_time()
        due[id(payload)] = start + t
        view.q.put((key, payload))
    end = encode(Control("end", "twin", {}))
    due[id(end)] = time.monotonic()
    view.q.put(("twin/ctl", end))
    runner.join()
    cpu = time.process_time() - (cpu0 or 0.0)
    rec.flush()
    rec.disconnect()
    scans = sum(1 for t, k, _ in heard if k.endswith("/truth") and t >= skip)
    ms = sorted(1e3 * x for x in late)
    return {"cpu_ms": 1e3 * cpu / max(1, scans), "late_median": statistics.median(ms),
            "late_p99": ms[int(0.99 * (len(ms) - 1))], "late_max": ms[-1],
            "flush_s": view.flush_s, "dropped": view.dropped, "skipped": view.skipped,
            "decimated": view.batcher.decimated}


VIEW_MODULES = ("view_columns", "view_state", "view")
"""The view's modules (``sensornet/<name>.py``), loaded from a git revision by
:func:`modules_at` to compare the drawing and the loop then and now on the same traffic."""


def modules_at(rev: str) -> tuple[type, type, type]:
    """``(Batcher, ViewState, LiveView)`` of the view's modules at git revision ``rev``
    (imported under other names, each importing the others' old versions; the rest of the
    package as now)."""
    root = Path(__file__).resolve().parents[1]
    loaded = {}
    for name in VIEW_MODULES:
        text = subprocess.run(["git", "-C", str(root), "show", f"{rev}:sensornet/{name}.py"],
                              capture_output=True, text=True, check=True).stdout
        for other in VIEW_MODULES:
            text = re.sub(rf"\bsensornet\.{other}\b", f"_at_rev_{other}", text)
        module = types.ModuleType(f"_at_rev_{name}")
        sys.modules[module.__name__] = module
        exec(compile(text, f"{rev}:sensornet/{name}.py", "exec"), module.__dict__)
        loaded[name] = module
    return (loaded["view_columns"].Batcher, loaded["view_state"].ViewState,
            loaded["view"].LiveView)


def draw(names: list[str], period: float, seconds: list[list[tuple[str, bytes]]], out: Path,
         every: int = 1, profile: int = 0, kinds: tuple = (Batcher, ViewState),
         skip: int = 0) -> tuple[float, Batcher, ViewState]:
    """Process CPU (s) of drawing ``seconds`` of traffic into a ``.rrd`` at ``out``, flushed
    every ``every`` seconds (``profile``: print the most costly functions; ``kinds``: the
    ``(Batcher, ViewState)`` classes; ``skip``: the CPU of the first seconds not counted, the
    recording's first flushes that make its entities)."""
    rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view-twin")
    rec.set_sinks(rr.FileSink(str(out)))
    b = kinds[0](rr, rec)
    state = kinds[1](b, names, period)
    prof = cProfile.Profile() if profile else None
    t0 = time.process_time()
    if prof is not None:
        prof.enable()
    for i, second in enumerate(seconds, start=1):
        for key, payload in second:
            state.receive(key, payload)
        if i % every == 0:
            b.flush()
        if i == skip:
            t0 = time.process_time()
    b.flush()
    rec.flush()
    if prof is not None:
        prof.disable()
    cpu = time.process_time() - t0
    rec.disconnect()
    if prof is not None:
        pstats.Stats(prof).sort_stats("tottime").print_stats(profile)
    return cpu, b, state


class _Nowhere:
    """A recorder that keeps nothing (:func:`handling`: the batcher's rows are never sent)."""

    def send_columns(self, path, indexes, columns) -> None:
        pass


def handling(names: list[str], period: float, heard: list[tuple[float, str, bytes]],
             kinds: tuple) -> float:
    """Thread CPU (s) of handling every message heard (decoding, :class:`ViewState`'s rows),
    nothing flushed: the part of the view's work a message costs, apart from Rerun."""
    state = kinds[1](kinds[0](rr, _Nowhere()), names, period)
    t0 = time.thread_time()
    for _, key, payload in heard:
        state.receive(key, payload)
    return time.thread_time() - t0


def rrd_rows(path: Path) -> dict[str, list]:
    """Entity -> its rows in a ``.rrd`` (time and data columns, row ids apart; sorted), the
    recording's properties left out: what two drawings must share to show the same picture."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    reader = RrdReader(str(path))
    (store,) = reader.recordings()
    for chunk in reader.stream(store=store):
        if chunk.entity_path == "/__properties":
            continue
        batch = chunk.to_record_batch()
        names = [f.name for f in batch.schema
                 if (f.metadata or {}).get(b"rerun:kind") != b"control"]
        cols = {n: batch.column(n).to_pylist() for n in names}
        out.setdefault(chunk.entity_path, []).extend(
            tuple(sorted((n, repr(cols[n][i])) for n in names)) for i in range(batch.num_rows))
    return {e: sorted(r) for e, r in out.items()}


def same_picture(names: list[str], period: float, seconds: list, sides: list) -> int:
    """``--same``: each side's drawing of the traffic through its :meth:`LiveView.flush` (the
    health series held as live), flushed every 1 and every 2 s, into a ``.rrd``, read back:
    the same entities, each with the same rows. Returns 0 if so, else 1 (the differing
    entities said)."""
    status = 0
    with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
        for every in (1, 2):
            got = {}
            for side, kinds in sides:
                out = Path(tmp) / f"{every}.rrd"
                rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view-same")
                rec.set_sinks(rr.FileSink(str(out)))
                view = kinds[2]("twin", None, rr, rec, say=lambda s: None)
                view.rr, view.rec, view.batcher = rr, rec, kinds[0](rr, rec)
                view.state = kinds[1](view.batcher, names, period)
                for i, second in enumerate(seconds, start=1):
                    for key, payload in second:
                        view._take(key, payload)
                    if i % every == 0:
                        view.flush_s = every * FLUSH_S  # as at this period throughout
                        view.flush()
                view.batcher.flush()
                rec.flush()
                rec.disconnect()
                got[side] = rrd_rows(out)
            (a, ra), (b, rb) = got.items()
            differ = sorted(e for e in set(ra) | set(rb) if ra.get(e) != rb.get(e))
            print(f"flushed every {every * FLUSH_S:g} s: {a} {len(ra)} entities, "
                  f"{sum(map(len, ra.values()))} rows; {b} {len(rb)}, "
                  f"{sum(map(len, rb.values()))}; entities whose rows differ: {len(differ)}"
                  + (f" ({', '.join(differ[:5])})" if differ else ""), flush=True)
            status |= bool(differ)
    return status


def series_every(names: list[str], period: float, heard: list[tuple[float, str, bytes]],
                 args) -> int:
    """``--series-every``: the real-time replay with :data:`sensornet.view.SERIES_EVERY` at
    each value given, interleaved; CPU per scan and lateness per run, then the medians."""
    values = [int(v) for v in args.series_every.split(",")]
    made = view_module.SERIES_EVERY
    cpu: dict[int, list[float]] = {v: [] for v in values}
    print("| series every | rep | CPU ms per scan | handled after due: median / p99 (ms) | "
          "flush period at the end (s) | load |\n|---:|---:|---:|---:|---:|---:|", flush=True)
    try:
        with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
            for rep in range(args.repeats):
                for v in values:
                    view_module.SERIES_EVERY = v
                    r = realtime(names, period, heard, Path(tmp) / "live.rrd",
                                 skip=args.skip * FLUSH_S)
                    cpu[v].append(r["cpu_ms"])
                    print(f"| {v} | {rep + 1} | {r['cpu_ms']:.1f} | {r['late_median']:.0f} / "
                          f"{r['late_p99']:.0f} | {r['flush_s']:g} | "
                          f"{os.getloadavg()[0]:.1f} |", flush=True)
    finally:
        view_module.SERIES_EVERY = made
    base = statistics.median(cpu[values[0]])
    print("\n" + ", ".join(f"every {v}: {statistics.median(cpu[v]):.1f} ms a scan "
                           f"({statistics.median(cpu[v]) / base:.2f})" for v in values))
    return 0


def main_twin(args) -> int:
    cache = Path(args.cache) if args.cache else None
    if cache is not None and cache.is_file():
        names, period, heard = pickle.loads(cache.read_bytes())
    else:
        names, period, heard = twin_traffic(args.peers, args.scans, args.hosts)
        if cache is not None:
            cache.write_bytes(pickle.dumps((names, period, heard)))
    if args.series_every:
        return series_every(names, period, heard, args)
    seconds = by_second(heard)
    if args.same:
        if not args.against:
            raise SystemExit("--same needs --against REV")
        return same_picture(names, period, seconds, [
            (args.against, modules_at(args.against)), ("now", (Batcher, ViewState, LiveView))])
    scans = max(1, sum(1 for s in seconds for k, _ in s if k.endswith("/truth")))
    n_msgs = sum(map(len, seconds))
    n_bytes = sum(len(p) for s in seconds for _, p in s)
    skip = args.skip
    counted = sum(1 for s in seconds[skip:] for k, _ in s if k.endswith("/truth"))
    sides = [("now", (Batcher, ViewState, LiveView))]
    if args.against:
        sides.insert(0, (args.against, modules_at(args.against)))
    cpu: dict[tuple[str, int], list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
        for _, kinds in sides:  # imports, first calls: not measured
            draw(names[:10], period, seconds[:2], Path(tmp) / "warm.rrd", kinds=kinds)
        if args.profile:
            draw(names, period, seconds, Path(tmp) / "profile.rrd", profile=args.profile)
        for _ in range(args.repeats):  # interleaved: the machine's load falls on every side
            for every in (1, 2):
                for side, kinds in sides:
                    used, b, state = draw(names, period, seconds, Path(tmp) / "t.rrd", every,
                                          kinds=kinds, skip=skip)
                    cpu.setdefault((side, every), []).append(1e3 * used / counted)
                    assert state.rejected == 0, state.rejected
        handled: dict[str, list[float]] = {}
        for _ in range(args.repeats if args.handling else 0):
            for side, kinds in sides:
                handled.setdefault(side, []).append(
                    1e3 * handling(names, period, heard, kinds) / scans)
        live = {side: realtime(names, period, heard, Path(tmp) / "live.rrd", kinds,
                               skip * FLUSH_S)
                for side, kinds in sides} if args.realtime else {}
    lines = [f"| {len(names)} peers, {scans} scans, hosts {args.hosts or 'none'}, CPU ms per "
             f"scan after the first {skip} s (min / median of {args.repeats}) | "
             + " | ".join(side for side, _ in sides) + " |",
             "|---|" + "---:|" * len(sides)]
    for every in (1, 2):
        lines.append(f"| flushed every {every * FLUSH_S:g} s | " + " | ".join(
            f"{min(cpu[side, every]):.1f} / {statistics.median(cpu[side, every]):.1f}"
            for side, _ in sides) + " |")
    if handled:
        lines.append(f"| handling the messages alone (thread CPU, all {scans} scans) | "
                     + " | ".join(f"{min(handled[side]):.2f} / "
                                  f"{statistics.median(handled[side]):.2f}"
                                  for side, _ in sides) + " |")
    for side, r in live.items():
        lines += ["", f"{side}: in real time through the view's loop (LiveView; "
                  f"{len(heard) / (heard[-1][0] or 1):.0f} messages/s): CPU "
                  f"{r['cpu_ms']:.1f} ms per scan after the first {skip * FLUSH_S:g} s, "
                  f"messages handled "
                  f"{r['late_median']:.0f} ms after due (median; p99 {r['late_p99']:.0f}, "
                  f"max {r['late_max']:.0f}), flushing every {r['flush_s']:g} s at the "
                  f"end; {r['dropped']} dropped, {r['decimated']} map frames decimated."]
    print("\n".join(lines) + f"\n\n{n_msgs} messages, {n_bytes / 1e6:.1f} MB heard; load "
          f"average {os.getloadavg()[0]:.1f}; 100 ms a scan at 10 scans/s")
    return 0


class _PerRow(Batcher):
    """The same rows, one ``rr.log`` each (the peers' way before issue 38)."""

    def _send(self, path, kind, ks, ts, data) -> None:
        rec = self.rec
        if kind == "ellipses":  # drawn as the batcher draws them, then logged a row each
            kind, data = "strips", ellipse_strips(data)
        for k, t, d in zip(ks, ts, data, strict=True):
            rec.set_time("scan", sequence=k)
            rec.set_time("sim", duration=t)
            if kind == "scalar":
                rec.log(path, rr.Scalars(d))
            elif kind == "points":
                rec.log(path, rr.Points2D(north_up(d[0]), colors=d[1], radii=d[2], labels=d[3],
                                          show_labels=d[3] is not None or None))
            elif kind == "strips":  # flat points, points per strip, colours, radius
                strips = np.split(d[0], np.cumsum(d[1])[:-1]) if len(d[1]) else []
                rec.log(path, rr.LineStrips2D(strips, colors=d[2], radii=d[3]))
            elif kind == "text":
                rec.log(path, rr.TextLog(d[0], level=d[1]))
            else:
                rec.log(path, rr.Transform3D(translation=d))
            self.calls += 1
        self.rows_sent += len(ks)


def run(peers: int, scans: int, per_row: bool, out: Path,
        flush_scans: int = 10) -> tuple[float, int]:
    rng = np.random.default_rng(0)
    data = messages(peers, scans, rng)
    rec = rr.RecordingStream("sensornet-bench", recording_id="bench-view")
    rec.set_sinks(rr.FileSink(str(out)))
    b = (_PerRow if per_row else Batcher)(rr, rec)
    state = ViewState(b, [f"p{i:03d}" for i in range(peers)], 0.1)
    t0 = time.process_time()
    for k, batch in enumerate(data, start=1):
        for key, payload in batch:
            state.receive(key, payload)
        if k % flush_scans == 0:  # 10: one flush a second at 10 scans/s
            b.flush()
    b.flush()
    rec.flush()
    cpu = time.process_time() - t0
    rec.disconnect()
    return cpu * 1e3 / scans, b.rows_sent


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--source", choices=("twin", "synthetic"), default="twin")
    p.add_argument("--peers", type=int, default=None, help="50 (twin), 100 (synthetic)")
    p.add_argument("--scans", type=int, default=None, help="60 (twin), 80 (synthetic)")
    p.add_argument("--hosts", type=int, default=2, help="twin: peer hosts (0: none)")
    p.add_argument("--cache", default=None, help="twin: keep the traffic in this file")
    p.add_argument("--profile", type=int, default=0, help="twin: print the N costliest")
    p.add_argument("--against", default=None, metavar="REV",
                   help="twin: also the drawing of git revision REV, interleaved")
    p.add_argument("--repeats", type=int, default=3, help="twin: draws of each side")
    p.add_argument("--realtime", action="store_true",
                   help="twin: also replay the traffic at its pace through the view's loop")
    p.add_argument("--same", action="store_true",
                   help="twin: only whether REV's drawing (--against) and today's write the "
                        "same entities and rows (flushes of 1 and 2 s, series held as live)")
    p.add_argument("--handling", action="store_true",
                   help="twin: also the messages' handling alone (decoding and rows, no "
                        "flush), --repeats times interleaved")
    p.add_argument("--skip", type=int, default=2,
                   help="twin: seconds not counted at the start (the entities' first flushes)")
    p.add_argument("--series-every", default=None, metavar="N,M",
                   help="twin: only the real-time replay, the health series sent every N "
                        "against every M flush periods of FLUSH_S (SERIES_EVERY), interleaved")
    args = p.parse_args(argv)
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    if args.source == "twin":
        args.peers, args.scans = args.peers or 50, args.scans or 60
        return main_twin(args)
    args.peers, args.scans = args.peers or 100, args.scans or 80
    with tempfile.TemporaryDirectory(prefix="sensornet-view-") as tmp:
        run(10, 10, False, Path(tmp) / "warm.rrd")  # imports and first calls, not measured
        naive, rows = run(args.peers, args.scans, True, Path(tmp) / "per-row.rrd")
        lines = [f"| {args.peers} peers, {args.scans} scans | CPU ms per scan | share of a "
                 f"core at 10 scans/s |", "|---|---:|---:|",
                 f"| one rr.log per row (the peers' way before) | {naive:.1f} | "
                 f"{naive / 100:.0%} |"]
        for every in (10, 20, 40, 80):  # the view doubles its period while a flush is long
            batched, _ = run(args.peers, args.scans, False, Path(tmp) / f"b{every}.rrd", every)
            lines.append(f"| batched, one send_columns per entity every {every / 10:g} s | "
                         f"{batched:.1f} | {batched / 100:.0%} |")
    print("\n".join(lines) + f"\n\n{rows} rows; load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
