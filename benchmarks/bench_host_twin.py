"""The peer hosts' CPU a peer-scan without Zenoh or a quiet machine (issues 33 and 38).

``bench_fifty.py`` measures 50 GM-PHD peers in two hosts of 25 as processes, which only a quiet
machine can do (a loaded one starves the hosts: scans skipped, deadline fusions, other code
paths). This runs the same network through the same host code (``peers.host.PeerHost``: its
delivery and hand-over, every peer's admission, runtime steps and telemetry, the stacked local
steps, the batched fusions and scores) in one process, without a session: a put goes to a stub
that hands a remote estimate to the other host's listeners (as its one subscriber would,
``HostDelivery._fan_out``), and time is virtual (every scan an interval later, each pass of the
loop at one instant, so no deadline fires however slow the machine). What it measures is the
hosts' process CPU a peer-scan and the peers' own CPU parts (``telemetry.cpu_ms``: estimate,
scan, publish, tick), which on a quiet machine came out as ``bench_fifty.py``'s (3.2 against
3.41 ms, estimate 1.82 / 1.84, scan 0.75 / 0.76): the loop's waits, Zenoh's threads and the
wire are what it leaves out. Every put's bytes are hashed: runs of two revisions that publish
the same bytes (and fused OSPA) compute the same thing, so their CPU ratio is the cost of the
change alone.

``--revs A,B`` alternates fresh processes of each revision (``.``: the working tree; a git
revision is exported to a temporary folder) ``--pairs`` times and prints each run, the medians
and the pair ratios B / A (load-independent up to the machine's noise: interleaved, one run).

    python benchmarks/bench_host_twin.py                          # HEAD against the tree
    python benchmarks/bench_host_twin.py --revs 770219a,HEAD --pairs 5
    python benchmarks/bench_host_twin.py --revs . --pairs 1 --set fusion.trust=false
    python benchmarks/bench_host_twin.py --revs . --pairs 1 --profile runs/host_twin.prof
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("tracking", "protocol", "peers", "sim")
"""The top-level folders the ``sensornet`` package maps (pyproject's package-dir)."""


class _Finder:
    """Imports ``sensornet`` (and its mapped subpackages) from a source folder ``root``
    instead of the installed one, so a child process runs another revision's code."""

    root = str(REPO)

    @classmethod
    def find_spec(cls, name, path=None, target=None):
        parts = name.split(".")
        if name == "sensornet":
            d = f"{cls.root}/sensornet"
        elif len(parts) == 2 and parts[0] == "sensornet" and parts[1] in PACKAGES:
            d = f"{cls.root}/{parts[1]}"
        else:
            return None
        return importlib.util.spec_from_file_location(name, f"{d}/__init__.py",
                                                      submodule_search_locations=[d])


def child(root: str, peers: int, degree: int, scans: int, hosts: int, sets: list[str],
          profile: str | None) -> dict:
    """One run of the hosts (module docstring) from the source folder ``root``; what
    :func:`main` prints of it. Patches ``time.time`` and ``time.monotonic``: a child only."""
    _Finder.root = root
    sys.meta_path.insert(0, _Finder)
    sys.path.insert(0, root)
    vt = [1_000_000.0]
    time.time = lambda: vt[0]
    time.monotonic = lambda: vt[0]
    import gc

    import numpy as np
    import sensornet.peers.host as hostmod
    from sensornet.peers.host import CONTROL, YOUNG_GC, PeerHost
    from sensornet.peers.runtime import RuntimeOptions
    from sensornet.protocol.codec import encode
    from sensornet.protocol.keys import Keys
    from sensornet.protocol.messages import Control, Scan
    from sensornet.sim.run.peers import make_peer
    from sensornet.sim.scenario import load_scenario, parse_overrides
    from sensornet.sim.world import generate_run

    from benchmarks.bench_network import scenario_text

    if not hostmod.__file__.startswith(root):
        raise RuntimeError(f"imported {hostmod.__file__}, not from {root}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "host_twin.toml"
        path.write_text(scenario_text(peers, degree, scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(["network.filter=gmphd",
                                                                  *sets]))
    names, net = scn.sensor_names, "hosttwin"
    keys, interval = Keys(net), scn.scan_period / scn.network.speed
    digest, puts = hashlib.sha256(), [0]

    class Pub:
        """A declared publisher's stand-in: hashes the put; a remote estimate to the other
        hosts' listeners (their queue, as Zenoh's callback would)."""

        def __init__(self, host, name: str, channel: str) -> None:
            self.host, self.name, self.channel = host, name, channel

        def put(self, payload: bytes, encoding=None) -> None:
            digest.update(f"{self.name}/{self.channel}".encode())
            digest.update(payload)
            puts[0] += 1
            if self.channel == "estimate":
                key = keys.estimate(self.name)
                for h in group:
                    if h is not self.host and key in h._remote:
                        h._deliver(h._remote[key], key, payload, backlog=False)

    size = -(-len(names) // hosts)
    group = [PeerHost(f"h{i + 1}", [(make_peer(scn, n, 0, network=net),
                                     RuntimeOptions(rerun=False, scan_period=scn.scan_period))
                                    for n in names[i * size:(i + 1) * size]],
                      ((), (), None, None, False), say=lambda line: None)
             for i in range(hosts)]
    for h in group:
        for rt in h.peers:
            rt.transport._pubs = {c: Pub(h, rt.name, c) for c in ("estimate", "tracks")}
        h._active = list(range(len(h.peers)))
    _, z = generate_run(scn, 0)

    def one_pass(h) -> bool:
        """One pass of ``PeerHost._run_loop`` at this instant; whether it had work."""
        moved = False
        while not h.q.empty():
            slot, item = h.q.get_nowait()
            if slot != CONTROL and slot in h._active:
                h._backlog[slot].append((time.time(), item))
                moved = True
        busy = (moved or any(h._backlog[i] for i in h._active)
                or (h.batch is not None and bool(h.batch.jobs)))
        h.counts["wakes"] += 1
        h._work(time.time(), time.monotonic())
        h._fuse_gathered()
        h._score()
        h._report()
        return busy

    def settle() -> None:
        for _ in range(100_000):
            if not any([one_pass(h) for h in group]):
                return
        raise RuntimeError("the hosts never went quiet")

    start = encode(Control("start", net, {"speed": scn.network.speed}, send_time=vt[0]))
    for h in group:
        h.cpu.start()
        for i, rt in enumerate(h.peers):
            rt.telemetry.start_cpu()
            for who in ("world", *rt.transport.neighbours):
                h.q.put((i, ("live", who, True)))
            rt.transport.deliver(keys.ctl(), start)
    settle()
    gc.collect()  # as PeerHost._loop: the start-up heap frozen, fewer young collections
    gc.freeze()
    gc.set_threshold(YOUNG_GC, *gc.get_threshold()[1:])
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    t0 = time.process_time()
    for k in range(1, scans + 1):
        vt[0] += interval
        for h in group:
            for rt in h.peers:
                i = names.index(rt.name)
                rt.transport.deliver(keys.scan(rt.name), encode(
                    Scan(rt.name, k, z[i][k - 1], seq=k, send_time=vt[0])))
        settle()
    cpu = time.process_time() - t0
    if prof is not None:
        prof.disable()
        prof.dump_stats(profile)
    rts = [rt for h in group for rt in h.peers]
    parts: dict[str, float] = {}
    for rt in rts:
        for c, v in rt.telemetry.cpu_ms.items():
            parts[c] = parts.get(c, 0.0) + v / len(rts) / scans
    return {"ms": cpu * 1e3 / len(rts) / scans,
            "parts": {c: round(v, 3) for c, v in sorted(parts.items(), key=lambda x: -x[1])
                      if v >= 0.001},
            "puts": puts[0], "bytes": digest.hexdigest()[:16],
            "ospa": float(np.mean([rt.core.mean_ospa("fused") for rt in rts])),
            "fewest_scans": min(rt.core.consensus.stats.scans for rt in rts),
            "deadline_fusions": sum(rt.core.consensus.stats.deadline_fusions for rt in rts)}


def source(rev: str, tmp: Path) -> str:
    """The folder holding revision ``rev``'s files (``.``: the working tree)."""
    if rev == ".":
        return str(REPO)
    out = tmp / rev.replace("/", "_")
    if not out.exists():
        out.mkdir()
        tar = subprocess.run(["git", "-C", str(REPO), "archive", rev], check=True,
                             capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(out)], input=tar, check=True)
    return str(out)


def load_average() -> str:
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "-"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--revs", default="HEAD,.",
                   help="revisions, comma-separated (. the working tree); ratios against "
                        "the first")
    p.add_argument("--pairs", type=int, default=3, help="alternated runs of each revision")
    p.add_argument("--scans", type=int, default=30)
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--degree", type=int, default=4)
    p.add_argument("--hosts", type=int, default=2)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a scenario override for every run (repeatable)")
    p.add_argument("--profile", metavar="FILE",
                   help="cProfile the last revision's last run's scans into FILE")
    p.add_argument("--child", metavar="ROOT", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        print(json.dumps(child(a.child, a.peers, a.degree, a.scans, a.hosts, a.set,
                               a.profile)))
        return 0
    revs = a.revs.split(",")
    print(f"## {a.peers} GM-PHD peers in {a.hosts} hosts, degree {a.degree}, 2 rounds, "
          f"{a.scans} scans, virtual time; load average {load_average()}\n")
    print("| rev | run | CPU ms/peer-scan | parts (ms) | puts | bytes | fused OSPA | "
          "fewest scans | deadline fusions | load |")
    print("|---|---:|---:|---|---:|---|---:|---:|---:|---:|")
    runs: dict[str, list[dict]] = {r: [] for r in revs}
    with tempfile.TemporaryDirectory() as tmp:
        roots = {r: source(r, Path(tmp)) for r in revs}
        for i in range(a.pairs):
            for r in (revs if i % 2 == 0 else revs[::-1]):
                last = i == a.pairs - 1 and r == revs[-1]
                cmd = [sys.executable, __file__, "--child", roots[r], "--scans", str(a.scans),
                       "--peers", str(a.peers), "--degree", str(a.degree),
                       "--hosts", str(a.hosts), *(f"--set={s}" for s in a.set),
                       *(["--profile", a.profile] if a.profile and last else [])]
                out = subprocess.run(cmd, capture_output=True, text=True, cwd=roots[r])
                if out.returncode:
                    print(out.stderr[-2000:], file=sys.stderr)
                    return 1
                x = json.loads(out.stdout.strip().splitlines()[-1])
                runs[r].append(x)
                parts = ", ".join(f"{c} {v:.2f}" for c, v in list(x["parts"].items())[:4])
                print(f"| {r} | {i + 1} | {x['ms']:.3f} | {parts} | {x['puts']} | "
                      f"{x['bytes']} | {x['ospa']:.3f} | {x['fewest_scans']} | "
                      f"{x['deadline_fusions']} | {load_average()} |", flush=True)
    base = revs[0]
    for r in revs[1:]:
        ratios = [y["ms"] / x["ms"] for x, y in zip(runs[base], runs[r], strict=True)]
        same = all(x["bytes"] == y["bytes"] and x["ospa"] == y["ospa"]
                   for x, y in zip(runs[base], runs[r], strict=True))
        print(f"\n{r} / {base}: median CPU {statistics.median(y['ms'] for y in runs[r]):.3f} / "
              f"{statistics.median(x['ms'] for x in runs[base]):.3f} ms a peer-scan, pair "
              f"ratios {', '.join(f'{q:.3f}' for q in ratios)} (median "
              f"{statistics.median(ratios):.3f}); the same bytes and OSPA: "
              f"{'yes' if same else 'NO'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
