"""50 peers in real time, labelled and watched (issues 33 and 38), measured in one run.

Runs 50 peers on a circulant graph of degree 4, 2 consensus rounds, 10 scans/s, packed in peer
hosts (``sensornet run``'s automatic packing unless ``--per-process``; its default links, gossip
on, so that the view, which connects to the world, finds the hosts), for each peer kind
(GM-PHD with tags and LMB, ``network.filter``) with the live view off and on, and prints one
row per run:

- scans handled per peer (the fewest), deadline fusions (all peers pooled, and the worst peer),
  p50 / p99 scan -> fused tracks (every peer's samples pooled) and the worst peer's own p99,
  mean fused OSPA;
- the peers' CPU per peer-scan (their hosts' CPU split between their peers, from the loop's
  start: ``bench_network.cpu_per_scan``) and its largest parts;
- CPU seconds per wall second of every process of the run (world, hosts, view), sampled from
  ``/proc`` while the world sent its scans, against the 2.0 cores there are: the honest floor.
  A run that is not real time while this is well under 2.0 was starved by other work on the
  machine (the load average is printed beside every row), not by its own design;
- for view-on runs the view's CPU per scan and its lag behind the peers (``view_of``), and the
  messages it drew (about 150 per peer and 100 scans when it hears the peers; a view that hears
  only the world's scans and truth draws about one per sensor and scan).

Then the ratio rows measured in the same invocation: each view setting / off per kind, LMB /
GM-PHD per view setting (medians over the repeats).

``--views`` takes ``off``, ``on`` (the view as ``sensornet run`` starts it: every thread in
SCHED_IDLE), ``nice`` (the view before: its threads at nice 10, no ``--idle``) and ``discard``
(the view subscribes and drops every message unread: what the subscription alone costs the
peers, their reports and puts, without the view's drawing), so that the view's cost can be
told apart: the peers' side (``discard`` / ``off``) and the view's CPU beside them (``nice``
against ``on``).

``--gaps`` measures one LMB peer alone (no network): its step's CPU and OSPA when it leaves
scans out, as a host that fell behind does (``peers.runtime`` ``_catch_up``), with LBP on a
step after a gap (``LmbEstimator.filter_for``) and with Gibbs sampling on every step, each with
Gibbs at any cluster size, and as it is (Gibbs up to ``lmb_association.GIBBS_TRACKS`` tracks).

    python benchmarks/bench_fifty.py                       # 2 kinds x view off/on, 2 repeats
    python benchmarks/bench_fifty.py --kinds lmb --views off --repeats 3
    python benchmarks/bench_fifty.py --views off,discard,nice,on   # the view's cost apart
    python benchmarks/bench_fifty.py --per-process 50      # one host of 50
    python benchmarks/bench_fifty.py --speed 4             # the same at 4 scans/s
    python benchmarks/bench_fifty.py --gaps                # one LMB peer leaving scans out
    python benchmarks/bench_fifty.py --twin --repeats 3    # the peers' logic alone, per kind
    python benchmarks/bench_fifty.py --watched --against REV  # being watched, REV's and now

"Real time" is ``bench_network.real_time``: every peer handled every scan, at most 5 % of a
peer's fusions forced by the deadline, pooled p99 scan -> tracks under one scan interval.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import types
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_fifty.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import sensornet.sim.run.launcher as launcher
from sensornet.peers.host import SharedDecode
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.peers.telemetry import percentile
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.packing import choose, scenario_load
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.world import generate_run
from sensornet.tracking import lmb_association
from sensornet.tracking.metrics import ospa

import benchmarks.bench_watched as bench_watched
from benchmarks.bench_network import (
    cpu_per_scan,
    load_average,
    real_time,
    scenario_text,
    speed_probe,
    view_of,
)

CORES = 2.0
"""Cores of the machine the targets are stated for."""
TICK = os.sysconf("SC_CLK_TCK")
VIEWS = ("off", "on", "nice", "discard")
"""The view settings of ``--views`` (module docstring)."""


def proc_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` (its own threads; /proc/PID/stat fields
    14 and 15), None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rsplit(")", 1)[1].split()  # the name may hold spaces: cut after it
    return (int(fields[11]) + int(fields[12])) / TICK


@dataclass
class CpuSampler:
    """Samples every process of a run handle (its members and its view) every ``period``
    seconds from a thread: ``samples`` of (wall time, {name: CPU seconds})."""

    handle: object
    period: float = 0.25
    samples: list[tuple[float, dict[str, float]]] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)

    def start(self) -> CpuSampler:
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            procs = {**self.handle.procs, **getattr(self.handle, "views", {})}
            now = time.monotonic()
            cpu = {n: c for n, p in procs.items() if (c := proc_cpu_s(p.pid)) is not None}
            self.samples.append((now, cpu))
            self._stop.wait(self.period)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def window(self, t0: float, t1: float) -> tuple[float, dict[str, float]]:
        """CPU seconds per wall second of each process between the samples nearest ``t0``
        and ``t1`` (a process gone before ``t1`` counts to its last sample), and the span."""
        if len(self.samples) < 2:
            return float("nan"), {}
        a = min(self.samples, key=lambda s: abs(s[0] - t0))
        b = min(self.samples, key=lambda s: abs(s[0] - t1))
        span = b[0] - a[0]
        if span <= 0:
            return float("nan"), {}
        last: dict[str, float] = {}
        for t, cpu in self.samples:
            if t <= b[0]:
                last.update(cpu)
        return span, {n: (last[n] - a[1].get(n, 0.0)) / span for n in last if n in a[1]}


def scanning_window(samples: list[tuple[float, dict[str, float]]], world_start: float,
                    seconds: float, interval: float) -> tuple[float, float]:
    """The wall interval the world sent its scans in: the world leaves a fusion deadline
    (0.9 of an ``interval``) and about 0.3 s after its last scan (``World.end``), so the
    window ends then and lasts ``seconds``; clipped to the samples (``world_start``: when the
    world process started)."""
    alive = [t for t, cpu in samples if "world" in cpu]
    end = (alive[-1] if alive else world_start + seconds) - 0.9 * interval - 0.3
    return max(world_start, end - seconds), end


def view_command(view: str):
    """``launcher._view_command`` for view setting ``view``: ``nice`` without ``--idle``,
    ``discard`` with the diagnostic ``--discard``, ``on`` as it is."""
    made = launcher._view_command

    def command(*args, **kwargs) -> list[str]:
        cmd = made(*args, **kwargs)
        if view == "nice":
            return [a for a in cmd if a != "--idle"]
        return cmd + (["--discard"] if view == "discard" else [])

    return command


@dataclass
class Run:
    kind: str
    view: str
    repeat: int
    rows: dict
    ok: bool


def one_run(tmp: Path, kind: str, view: str, repeat: int, scans: int, per_process: int | None,
            degree: int, n: int, speed: float = 10.0, sparse: bool = False,
            sets: tuple[str, ...] = ()) -> Run:
    """One network run at ``speed`` scans/s with the view ``view`` (:data:`VIEWS`); its
    numbers in ``rows`` (module docstring); ``sets``: more scenario overrides (``KEY=VALUE``,
    as ``sensornet run --set``)."""
    tag = f"{kind}-{view}-{repeat}"
    path = tmp / f"fifty-{n}-{degree}-{speed:g}.toml"
    path.write_text(scenario_text(n, degree, scans, rounds=2, speed=speed))
    overrides = [f"network.filter={kind}", *sets]
    scn = load_scenario(str(path), overrides=parse_overrides(overrides))
    per = per_process or choose(n, None, load=scenario_load(scn)).per_process
    probe = speed_probe()
    load0 = load_average()
    made, launcher._view_command = launcher._view_command, view_command(view)
    try:
        handle = start_run(scn, str(path), tmp / tag, overrides=overrides, rerun=view != "off",
                           sparse=sparse, per_process=per)
    finally:
        launcher._view_command = made
    t_start = time.monotonic()
    sampler = CpuSampler(handle).start()
    try:
        codes = wait_run(handle, timeout=scans / speed + 120 + 3 * n)
    finally:
        handle.stop_all()
        sampler.stop()
    out = tmp / tag
    s = read_summaries(out, scn.sensor_names)
    res = {"codes": codes, "summaries": s, "scn": scn,
           "view": view_of(out) if view != "off" else None}
    ok, why, _ = real_time(res)
    interval = scn.scan_period / scn.network.speed
    t0, t1 = scanning_window(sampler.samples, t_start, scans * interval, interval)
    span, per_proc = sampler.window(t0, t1)
    total = sum(per_proc.values())
    row: dict = {"per": per, "ok": ok, "why": why, "load": f"{load0}-{load_average()}",
                 "probe": probe, "cpu_total": total, "span": span, "speed": speed,
                 "cores_at_10": total * 10.0 / speed,
                 "cpu_view": per_proc.get("view", float("nan")),
                 "cpu_world": per_proc.get("world", float("nan")),
                 "cpu_hosts": sum(v for k, v in per_proc.items() if k not in ("view", "world"))}
    if s:
        lat = sorted(x for v in s.values() for x in v.get("latency_ms_samples") or [])
        fus = sum(v["stats"].get("fusions", 0) for v in s.values())
        late = sum(v["stats"].get("deadline_fusions", 0) for v in s.values())
        worst = max(v["stats"]["deadline_fusions"] / max(1, v["scans"]) for v in s.values())
        cpu, parts = cpu_per_scan(s)
        ospa = [v["mean_ospa_fused"] for v in s.values() if v.get("mean_ospa_fused") is not None]
        row |= {"min_scans": min(v["scans"] for v in s.values()), "peers": len(s),
                "late": late / max(1, fus), "late_worst": worst,
                "p50": statistics.median(lat) if lat else float("nan"),
                "p99": percentile(lat, 0.99) if lat else float("nan"),
                "p99_worst": max((percentile(sorted(v["latency_ms_samples"]), 0.99)
                                  for v in s.values() if v.get("latency_ms_samples")),
                                 default=float("nan")),
                "cpu_peer": cpu, "parts": parts,
                "ospa": statistics.fmean(ospa) if ospa else float("nan")}
    row["view"] = res["view"] or {}
    log = out / "logs" / "view.log"
    drawn = re.search(r"(\d+) messages drawn", log.read_text()) if log.is_file() else None
    row["view"]["drawn"] = int(drawn.group(1)) if drawn else -1
    return Run(kind, view, repeat, row, ok)


HEADER = ("| kind | view | rep | scans/s | per host | real time | fewest scans | deadline fusions "
          "(all / worst peer) | p50 / p99 / worst peer's p99 scan->tracks (ms) | "
          "peers' CPU ms/peer-scan | "
          "top parts (ms) | CPU s per wall s: hosts + world + view | peers' work at 10 scans/s "
          "(cores of 2.0) | fused OSPA | view CPU ms/scan | view lag median / p99 (ms) | "
          "view messages drawn | "
          "load avg start-end | probe (ms) |")
RULE = "|" + "---|" * 6 + "---:|" * 13


def fmt(r: Run, n: int) -> str:
    """One table row of run ``r`` of ``n`` peers (see :data:`HEADER`)."""
    x, nan = r.rows, float("nan")
    v = x["view"]
    parts = sorted((x.get("parts") or {}).items(), key=lambda kv: -kv[1])[:3]
    top = ", ".join(f"{k} {ms:.2f}" for k, ms in parts)
    view_cols = "- | - | -"
    if r.view != "off":
        view_cols = (f"{v.get('cpu_ms_per_scan', nan):.1f} | {v.get('lag_median_ms', nan):.0f} "
                     f"/ {v.get('lag_p99_ms', nan):.0f} | {v.get('drawn', -1)}")
    work = x.get("cpu_peer", nan) * n * 10.0 / 1e3
    return (f"| {r.kind} | {r.view} | {r.repeat + 1} | {x['speed']:g} | "
            f"{x['per']} | {'yes' if r.ok else 'NO'} | {x.get('min_scans', '-')} | "
            f"{100 * x.get('late', nan):.1f} / {100 * x.get('late_worst', nan):.1f} % | "
            f"{x.get('p50', nan):.1f} / {x.get('p99', nan):.1f} / "
            f"{x.get('p99_worst', nan):.1f} | {x.get('cpu_peer', nan):.2f} | "
            f"{top} | {x['cpu_total']:.2f} = {x['cpu_hosts']:.2f} + {x['cpu_world']:.2f} + "
            f"{x['cpu_view'] if r.view != 'off' else 0.0:.2f} | {work:.2f} | "
            f"{x.get('ospa', nan):.2f} | "
            f"{view_cols} | {x['load']} | {x['probe']:.0f} |")


def ratio_rows(runs: list[Run], kinds: list[str], views: list[str]) -> list[str]:
    """Medians over repeats of the CPU per peer-scan, p99 and CPU per wall second: each view
    setting / off per kind and LMB / GM-PHD per view setting."""
    def med(kind: str, view: str, key: str) -> float:
        xs = [r.rows.get(key, float("nan")) for r in runs if r.kind == kind and r.view == view]
        xs = [x for x in xs if x == x]
        return statistics.median(xs) if xs else float("nan")

    keys = (("cpu_peer", "peers' CPU/peer-scan"), ("p99", "p99 scan->tracks"),
            ("cpu_total", "CPU s per wall s"))
    rows = ["| ratio | " + " | ".join(k[1] for k in keys) + " |", "|---|" + "---:|" * len(keys)]
    if "off" in views:
        for kind in kinds:
            for view in (v for v in views if v != "off"):
                rows.append(f"| {kind}: view {view} / off | " + " | ".join(
                    f"{med(kind, view, k) / med(kind, 'off', k):.2f}" for k, _ in keys) + " |")
    if "lmb" in kinds and "gmphd" in kinds:
        for view in views:
            rows.append(f"| lmb / gmphd, view {view} | " + " | ".join(
                f"{med('lmb', view, k) / med('gmphd', view, k):.2f}" for k, _ in keys) + " |")
    return rows


GAP_PATTERNS = (("every scan", lambda k: 1), ("a gap of 5 every 10 scans",
                                              lambda k: 5 if k % 10 == 9 else 1),
                ("every 3rd scan", lambda k: 3), ("every 5th scan", lambda k: 5))
"""Scan patterns of :func:`part_gaps`: the step from scan ``k`` to the next one taken."""


GAP_DESIGNS = tuple(f"{where}, Gibbs {size}" for where in ("Gibbs on every step",
                                                             "LBP after a gap")
                    for size in ("at any size", f"<= {lmb_association.GIBBS_TRACKS} tracks"))
"""Designs of :func:`part_gaps`: Gibbs sampling on every step (the design before b907a9f) or
LBP on a step after a gap (``LmbEstimator.filter_for``), each with Gibbs on loopy clusters of
any size (before the bound) or of at most ``lmb_association.GIBBS_TRACKS`` tracks; the last is
the estimator as it is."""


def part_gaps(sensors: int = 4) -> list[str]:
    """One LMB peer's step (``LmbEstimator.step``, thread CPU) on the 50-peer scenario's
    scans of ``sensors`` sensors when it leaves scans out, as a host catching up does, per
    design of :data:`GAP_DESIGNS`, with the OSPA (c = 100 m) of its tracks and the Gibbs
    calls made: all, on clusters beyond ``GIBBS_TRACKS`` tracks (what the bound leaves to LBP)
    and the largest cluster's tracks."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "gaps.toml"
        path.write_text(scenario_text(50, 4, 100, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(["network.filter=lmb"]))
    truth, scans = generate_run(scn, 0)
    cap = lmb_association.GIBBS_TRACKS
    rows = ["| scans stepped | design | step CPU ms: median / mean / p99 / max | OSPA (m) | "
            f"Gibbs calls / on more than {cap} tracks / largest |", "|---|---|---:|---:|---:|"]
    print("\n".join(rows), flush=True)
    sampled: list[int] = []
    gibbs = lmb_association.marginals_gibbs

    def counted(miss, detect, *args, **kwargs):
        sampled.append(detect.shape[0])
        return gibbs(miss, detect, *args, **kwargs)

    lmb_association.marginals_gibbs = counted
    try:
        for name, pattern in GAP_PATTERNS:
            for design in GAP_DESIGNS:
                ts, errs = [], []
                sampled.clear()
                for i in range(sensors):
                    est = LmbEstimator(make_lmb_filter(scn, scn.sensor_names[i], i))
                    if design.endswith("at any size"):
                        est.filter = dataclasses.replace(est.filter, gibbs_tracks=None)
                    if design.startswith("Gibbs on every step"):
                        est.filter_for = lambda k, e=est: e.filter
                    k, prev = 0, -1
                    while k < scn.num_scans:
                        est.begin_scan(k)
                        t0 = time.thread_time()
                        out = est.step(max(1, k - prev), scans[i][k])
                        ts.append(time.thread_time() - t0)
                        X = est.extract(out.density)
                        errs.append(ospa(X[:, [0, 2]], truth.states[k][:, [0, 2]], c=100.0))
                        prev, k = k, k + pattern(k)
                t = np.array(ts) * 1e3
                rows.append(f"| {name} | {design} | {np.median(t):.2f} / {t.mean():.2f} / "
                            f"{np.percentile(t, 99):.1f} / {t.max():.1f} | "
                            f"{np.mean(errs):.1f} | {len(sampled)} / "
                            f"{sum(x > cap for x in sampled)} / {max(sampled, default=0)} |")
                print(rows[-1], flush=True)
    finally:
        lmb_association.marginals_gibbs = gibbs
    return rows


def part_twin(kinds: list[str], repeats: int, n: int = 50, degree: int = 4,
              scans: int = 100, sets: tuple[str, ...] = ()) -> list[str]:
    """The peers' logic alone: the twin (``sim.run.twin``, a virtual clock, no transport) of
    the same network, every peer decoding through one shared decode and the rounds ready at
    one instant fused together, as co-hosted peers do: process CPU per peer-scan and mean
    fused OSPA per kind, kinds interleaved ``repeats`` times; then LMB / GM-PHD (medians).
    ``sets``: more scenario overrides (``--set``; ignored before 5 Dec, so earlier twin rows
    ran the scenario's defaults).
    What a network that keeps up costs in its peers' logic, whatever the machine's load."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, degree, scans, rounds=2, speed=10.0))
        scns = {kind: load_scenario(str(path), overrides=parse_overrides(
            [f"network.filter={kind}", *sets])) for kind in kinds}
    rows = ["| kind | rep | logic CPU ms/peer-scan | fused OSPA | load avg |",
            "|---|---:|---:|---:|---:|"]
    print("\n".join(rows), flush=True)
    ms: dict[str, list[float]] = {k: [] for k in kinds}
    for rep in range(repeats):
        for kind in kinds:
            scn = scns[kind]
            peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
            shared = SharedDecode()
            for core in peers.values():
                core.decode = shared
            t0 = time.process_time()
            result = run_twin(scn, 0, peers=peers, batch=True)
            ms[kind].append((time.process_time() - t0) * 1e3 / n / scans)
            ospa_f = statistics.fmean(result.mean_ospa(q) for q in scn.sensor_names)
            rows.append(f"| {kind} | {rep + 1} | {ms[kind][-1]:.2f} | {ospa_f:.2f} | "
                        f"{load_average()} |")
            print(rows[-1], flush=True)
    if "lmb" in ms and "gmphd" in ms:
        rows.append(f"\nLMB / GM-PHD logic CPU: "
                    f"{statistics.median(ms['lmb']) / statistics.median(ms['gmphd']):.2f}")
        print(rows[-1], flush=True)
    return rows


def observer_at(rev: str) -> types.ModuleType:
    """``peers/observer.py`` of git revision ``rev``, imported under another name (the rest
    of the package as now)."""
    root = Path(__file__).resolve().parents[1]
    text = subprocess.run(["git", "-C", str(root), "show", f"{rev}:peers/observer.py"],
                          capture_output=True, text=True, check=True).stdout
    module = types.ModuleType("_observer_at_rev")
    exec(compile(text, f"{rev}:peers/observer.py", "exec"), module.__dict__)
    return module


def part_watched(repeats: int, against: str | None, n: int = 50, degree: int = 4,
                 scans: int = 40, sets: tuple[str, ...] = ()) -> list[str]:
    """What being watched costs the peers themselves (issue 38): the twin of the network with
    every peer watched (``bench_watched.watched_twin``, two hosts), the observers' gathering
    and flushing CPU per peer-scan and the bytes they send, with today's observer and
    (``against``) revision REV's, interleaved ``repeats`` times; medians and their ratio."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "watched.toml"
        path.write_text(scenario_text(n, degree, scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(list(sets)))
    sides = [("now", (bench_watched.Observer, bench_watched.HostReports))]
    if against:
        old = observer_at(against)
        sides.insert(0, (against, (old.Observer, old.HostReports)))
    rows = ["| observer | rep | gather + flush ms/peer-scan | bytes/peer-scan | load |",
            "|---|---:|---:|---:|---:|"]
    print("\n".join(rows), flush=True)
    ms: dict[str, list[float]] = {side: [] for side, _ in sides}
    now = sides[-1][1]
    try:
        for rep in range(repeats):
            for side, (obs, host) in sides:
                bench_watched.Observer, bench_watched.HostReports = obs, host
                sent: list[int] = []
                cpu = bench_watched.watched_twin(
                    scn, 0, 2, lambda t, k, b, sent=sent: sent.append(len(b)))
                ms[side].append((cpu["gather"] + cpu["flush"]) * 1e3 / n / scans)
                rows.append(f"| {side} | {rep + 1} | {ms[side][-1]:.3f} | "
                            f"{sum(sent) / n / scans:.0f} | {load_average()} |")
                print(rows[-1], flush=True)
    finally:
        bench_watched.Observer, bench_watched.HostReports = now
    if against:
        rows.append(f"\nnow / {against}: "
                    f"{statistics.median(ms['now']) / statistics.median(ms[against]):.2f}")
        print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--kinds", default="gmphd,lmb", help="network.filter values (default both)")
    p.add_argument("--views", default="off,on",
                   help="the live view's settings, comma-separated: off, on (SCHED_IDLE, as run "
                        "starts it), nice (nice 10, the view before), discard (subscribes, "
                        "drops everything)")
    p.add_argument("--repeats", type=int, default=2, help="runs of each kind x view")
    p.add_argument("--scans", type=int, default=100, help="scans per run (default 100)")
    p.add_argument("--peers", type=int, default=50, help="peers (default 50)")
    p.add_argument("--degree", type=int, default=4, help="graph degree (default 4)")
    p.add_argument("--speed", type=float, default=10.0,
                   help="scans per second (default 10; lower: the CPU a scan costs when the "
                        "network keeps up, on a machine too busy for 10)")
    p.add_argument("--sparse", action="store_true",
                   help="links along the peer graph only, gossip off (sensornet run --sparse); "
                        "the view then links to the world alone and hears no peer (its "
                        "numbers are the world's scans and truth only)")
    p.add_argument("--keep", metavar="DIR", help="keep the runs' folders under DIR")
    p.add_argument("--per-process", type=int, default=None, metavar="N",
                   help="peers per host (default: sensornet run's choice for the kind)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="a scenario override for every run, as sensornet run --set (repeatable; "
                        "e.g. fusion.trust=false to price the defence)")
    p.add_argument("--gaps", action="store_true",
                   help="only one LMB peer's step when it leaves scans out (no network)")
    p.add_argument("--twin", action="store_true",
                   help="only the peers' logic: the twin of the network per kind (no processes)")
    p.add_argument("--watched", action="store_true",
                   help="only what being watched costs the peers on the twin (their reports' "
                        "gathering and flushing), today's observer and --against REV's")
    p.add_argument("--against", metavar="REV", default=None,
                   help="--watched: also the observer of this git revision, interleaved")
    args = p.parse_args(argv)
    if args.twin:
        print(f"## the twin of {args.peers} peers, degree {args.degree}, 2 rounds, {args.scans} "
              f"scans{''.join(' --set ' + x for x in args.sets)}; load average "
              f"{load_average()}\n")
        part_twin(args.kinds.split(","), args.repeats, args.peers, args.degree, args.scans,
                  tuple(args.sets))
        return 0
    if args.watched:
        print(f"## being watched on the twin of {args.peers} peers (2 hosts), degree "
              f"{args.degree}, 2 rounds, {min(args.scans, 40)} scans; load average "
              f"{load_average()}\n")
        part_watched(args.repeats, args.against, args.peers, args.degree, min(args.scans, 40),
                     tuple(args.sets))
        return 0
    if args.gaps:
        print(f"## one LMB peer's step with scans left out; load average {load_average()}\n")
        part_gaps()  # prints its rows as they come
        return 0
    kinds = args.kinds.split(",")
    views = args.views.split(",")
    if bad := [v for v in views if v not in VIEWS]:
        p.error(f"--views: {bad[0]!r} is not one of {', '.join(VIEWS)}")
    print(f"## {args.peers} peers, degree {args.degree}, 2 rounds, {args.speed:g} scans/s, "
          f"{args.scans} "
          f"scans, peer hosts{''.join(' --set ' + x for x in args.sets)}; load average "
          f"{load_average()} at the start\n", flush=True)
    print(HEADER, RULE, sep="\n", flush=True)
    runs: list[Run] = []
    with tempfile.TemporaryDirectory(prefix="sensornet-fifty-") as tmp:
        if args.keep:
            tmp = args.keep
            Path(tmp).mkdir(parents=True, exist_ok=True)
        for rep in range(args.repeats):  # interleaved, so drift hits every setting alike
            for kind in kinds:
                for view in views:
                    r = one_run(Path(tmp), kind, view, rep, args.scans, args.per_process,
                                args.degree, args.peers, args.speed, args.sparse,
                                tuple(args.sets))
                    runs.append(r)
                    print(fmt(r, args.peers), flush=True)
                    if not r.ok:
                        print(f"<!-- {r.kind} view {r.view}: "
                              f"{r.rows['why']} -->", flush=True)
    print()
    print("\n".join(ratio_rows(runs, kinds, views)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
