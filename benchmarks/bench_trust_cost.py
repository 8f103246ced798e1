"""What the defence against lying neighbours (``fusion.trust``) costs a peer-scan, per peer and
host-batched.

The twin (``sim.run.twin``, a virtual clock, no transport; the peers of one host: a shared
decode, batched rounds, as a peer host runs them) of ``n`` LMB peers (``--filter gmphd``:
GM-PHD) on a circulant graph of degree 4, 2 consensus rounds, run three ways in ONE process,
interleaved ``--repeats`` times: trust off, trust on with each peer's trust test on its own
(:meth:`peers.trust.Trust.weigh` per round, as before the host batching:
``FusionBatch.trust_together`` off) and trust on as a host runs it (the rounds of one
instant tested together, :func:`peers.trust_batch.weigh_together`). Prints per run the
process CPU per peer-scan, then the medians and the ratios; and whether the per-peer and
host-batched runs published the same fused states to the bit and ended with the same trust
states, scores and state changes (the batching must change no number). Both trust-on runs
take :attr:`TrustConfig.test_once` at its default (on: a full test once a scan where round 1
found nothing); ``--every-round`` adds a host-batched run with it off.

    python benchmarks/bench_trust_cost.py                      # 50 peers, 40 scans, 2 repeats
    python benchmarks/bench_trust_cost.py --peers 20 --scans 20 --repeats 1
    python benchmarks/bench_trust_cost.py --peers 20 --scans 30 --repeats 1 --lie p02:biased
    python benchmarks/bench_trust_cost.py --every-round   # also TrustConfig.test_once off
    python benchmarks/bench_trust_cost.py --filter gmphd  # GM-PHD peers (bench_fifty's kind)
    python benchmarks/bench_trust_cost.py --filter gmphd --ops   # the host-batched tests split
    python benchmarks/bench_trust_cost.py --filter gmphd --against 5d4d6eb --repeats 4
    python benchmarks/bench_trust_cost.py --filter gmphd --against 3f0c1a2 --batch 12

``--ops``: the host-batched runs' trust tests split by what a host computes stacked (each
request kind of :data:`peers.trust_batch.TOGETHER`, thread CPU per peer-scan and calls) and
the rest (the peers' generators and the lockstep between them: per-peer Python).

``--against REV``: instead, per repeat trust off, then the host-batched run with REV's stacked
requests (``peers/trust_batch.py``'s :data:`TOGETHER` at REV with ``peers/trust_checks.py``
at REV, the rest of the tree as now) and with today's, in alternating order in this one
process; per run the CPU and the trust tests' own CPU per peer-scan, whether the two
published the same fused states and trust summaries, then the medians and the ratios
today / REV.

``--batch N``: a host-batched pass tests at most ``N`` rounds together (the twin's pass holds
every peer's rounds; a real host of 25 peers batches 12-15 a pass), the rest in further
calls of ``N``: where the stacked requests' fixed cost a call shows.

``--young N``: instead, trust on and host-batched, with CPython's generation-0 collection
threshold and with ``N`` (a host's :data:`peers.host.YOUNG_GC`), alternated in this one
process, the heap frozen first as a host does (``gc.freeze()``): per run the CPU and the time
inside collections (``gc.callbacks``) per peer-scan and the process RSS, then the medians.

    python benchmarks/bench_trust_cost.py --filter gmphd --young 10000 --repeats 4

``--batches N,M,..``: instead, trust on and host-batched with at most ``N``, ``M``, .. rounds a
call, alternated in this one process: per run and round (0: the full test with the
once-a-scan tests; 1: mostly :attr:`TrustConfig.test_once`'s guard) the trust tests' thread
CPU per round and per call, then the fit ``per round = variable + fixed / batch`` over the
sizes (least squares on the medians): what a call costs whatever its size (the stacked
requests' and the lockstep's fixed part) and what each round adds.

    python benchmarks/bench_trust_cost.py --filter gmphd --batches 12,25,50 --repeats 2
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import statistics
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_trust_cost.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers import batching, trust_batch
from sensornet.peers.batching import FusionBatch
from sensornet.peers.host import SharedDecode
from sensornet.peers.trust import Trust
from sensornet.peers.trust_batch import weigh_together
from sensornet.sim.run import twin
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario

from benchmarks.bench_network import load_average, scenario_text


def one_run(path: Path, trust_on: bool, n: int, scans: int, lie: str | None = None,
            once: bool | None = None, together: bool = True, kind: str = "lmb",
            batch: int | None = None):
    """One twin run (``lie``: ``fusion.lie``, e.g. ``p02:biased``; ``once``: the peers'
    :attr:`TrustConfig.test_once`, None: the default; ``together``: the rounds' trust
    tests host-batched, else each on its own; ``kind``: ``network.filter``; ``batch``: at
    most this many rounds a :func:`weigh_together` call): CPU ms per peer-scan, the fused
    states and the trust summaries."""
    over = {"network.filter": kind, "fusion.trust": trust_on}
    if lie:
        over["fusion.lie"] = lie
    scn = load_scenario(str(path), overrides=over)
    peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
    shared = SharedDecode()
    for core in peers.values():
        core.decode = shared
        if once is not None and core.consensus.trust is not None:
            core.consensus.trust.cfg = dataclasses.replace(core.consensus.trust.cfg,
                                                           test_once=once)
    twin.FusionBatch = lambda: FusionBatch(trust_together=together)  # the twin's batch
    spent = [0.0]
    batching.weigh_together = _timed(_chunked(weigh_together, batch), spent)
    Trust.weigh = _timed(WEIGH, spent)
    try:
        t0 = time.process_time()
        result = twin.run_twin(scn, 0, peers=peers, batch=True)
        ms = (time.process_time() - t0) * 1e3 / n / scans
    finally:
        twin.FusionBatch = FusionBatch
        batching.weigh_together, Trust.weigh = weigh_together, WEIGH
    TESTS.append(spent[0] * 1e3 / n / scans)
    summaries = {}
    for q, core in peers.items():
        tr = core.consensus.trust
        if tr is not None:
            tr.finish()
            summaries[q] = tr.summary()
    return ms, result.tracks, summaries


WEIGH = Trust.weigh
TESTS: list[float] = []
OPS: dict[str, list[float]] = {}
"""With ``--ops``: per request kind, its thread CPU (s) and calls in the last run."""


def _count_ops() -> dict:
    """:data:`peers.trust_batch.TOGETHER`'s computations wrapped to add their thread CPU
    to :data:`OPS` (``trust_batch.TOGETHER`` is looked up per request); the originals."""
    saved = dict(trust_batch.TOGETHER)
    OPS.clear()
    for op, f in saved.items():
        def timed(args, f=f, op=op):
            t0 = time.thread_time()
            try:
                return f(args)
            finally:
                v = OPS.setdefault(op, [0.0, 0])
                v[0] += time.thread_time() - t0
                v[1] += 1
        trust_batch.TOGETHER[op] = timed
    return saved


def print_ops(n: int, scans: int) -> None:
    """The last host-batched run's trust tests split (:data:`OPS`) in ms per peer-scan."""
    total = sum(v[0] for v in OPS.values()) * 1e3 / n / scans
    print("| request (host-batched) | ms/peer-scan | calls |\n|---|---:|---:|")
    for op, (t, c) in sorted(OPS.items(), key=lambda kv: -kv[1][0]):
        print(f"| {op} | {t * 1e3 / n / scans:.4f} | {c} |")
    print(f"| all stacked requests | {total:.4f} | |\n| generators and lockstep (the rest) "
          f"| {TESTS[-1] - total:.4f} | |", flush=True)
"""Per run: the CPU ms per peer-scan of the trust tests themselves (every
:meth:`Trust.weigh` and :func:`peers.trust_batch.weigh_together`)."""


def _chunked(f, batch: int | None):
    """``f`` (:func:`weigh_together`) called on at most ``batch`` rounds at a time (None:
    all at once), the results in order."""
    if batch is None:
        return f
    return lambda calls: [w for lo in range(0, len(calls), batch)
                          for w in f(calls[lo:lo + batch])]


def _timed(f, spent: list[float]):
    """``f`` with its process CPU time added to ``spent[0]`` (a handful of calls a scan)."""
    def timed(*args, **kwargs):
        t0 = time.process_time()
        try:
            return f(*args, **kwargs)
        finally:
            spent[0] += time.process_time() - t0
    return timed


def same_tracks(a: dict, b: dict) -> bool:
    """Whether two runs published the same fused states, bit for bit."""
    return a.keys() == b.keys() and all(
        a[q].keys() == b[q].keys() and all(np.array_equal(a[q][k], b[q][k]) for k in a[q])
        for q in a)


def together_at(rev: str) -> dict:
    """:data:`peers.trust_batch.TOGETHER` of ``peers/trust_batch.py`` at git revision ``rev``
    with the stacked computations of ``peers/trust_checks.py`` at ``rev`` (both imported
    under other names; what they import, as now)."""
    root = Path(__file__).resolve().parents[1]
    checks = _module_at(root, rev, "peers/trust_checks.py", "_trust_checks_at_rev")
    text = subprocess.run(["git", "-C", str(root), "show", f"{rev}:peers/trust_batch.py"],
                          capture_output=True, text=True, check=True).stdout
    text = text.replace("from sensornet.peers.trust_checks import",
                        f"from {checks.__name__} import")
    module = types.ModuleType("_trust_batch_at_rev")
    sys.modules[module.__name__] = module
    exec(compile(text, f"{rev}:peers/trust_batch.py", "exec"), module.__dict__)
    return dict(module.TOGETHER)


def _module_at(root: Path, rev: str, path: str, name: str) -> types.ModuleType:
    """``path`` at git revision ``rev``, imported as module ``name``."""
    text = subprocess.run(["git", "-C", str(root), "show", f"{rev}:{path}"],
                          capture_output=True, text=True, check=True).stdout
    module = types.ModuleType(name)
    sys.modules[name] = module
    exec(compile(text, f"{rev}:{path}", "exec"), module.__dict__)
    return module


def against(path: Path, rev: str, n: int, scans: int, repeats: int, lie: str | None,
            kind: str, batch: int | None = None) -> None:
    """``--against REV``: trust off, REV's stacked requests and today's, alternated."""
    now, old = dict(trust_batch.TOGETHER), together_at(rev)
    ms: dict[str, list[float]] = {"off": [], rev: [], "now": []}
    tests: dict[str, list[float]] = {rev: [], "now": []}
    print("| run | rep | CPU ms/peer-scan | of which trust tests |\n|---|---:|---:|---:|",
          flush=True)
    try:
        for rep in range(repeats):
            v, _, _ = one_run(path, False, n, scans, lie, kind=kind, batch=batch)
            ms["off"].append(v)
            print(f"| off | {rep + 1} | {v:.3f} | |", flush=True)
            got = {}
            for side in ((rev, "now") if rep % 2 == 0 else ("now", rev)):
                trust_batch.TOGETHER.clear()
                trust_batch.TOGETHER.update(old if side == rev else now)
                v, tracks, summ = one_run(path, True, n, scans, lie, kind=kind, batch=batch)
                got[side] = (tracks, summ)
                ms[side].append(v)
                tests[side].append(TESTS[-1])
                print(f"| on, {side} | {rep + 1} | {v:.3f} | {TESTS[-1]:.3f} |", flush=True)
            print(f"{rev} vs now: fused states identical: "
                  f"{same_tracks(got[rev][0], got['now'][0])}, trust summaries identical: "
                  f"{got[rev][1] == got['now'][1]}", flush=True)
    finally:
        trust_batch.TOGETHER.clear()
        trust_batch.TOGETHER.update(now)
    med = {k: statistics.median(v) for k, v in ms.items()}
    t = {k: statistics.median(v) for k, v in tests.items()}
    print(f"\nmedians: off {med['off']:.3f}, on {rev} {med[rev]:.3f}, on now {med['now']:.3f} "
          f"ms/peer-scan (now / {rev} {med['now'] / med[rev]:.3f}); the defence (on - off): "
          f"{rev} {med[rev] - med['off']:.3f}, now {med['now'] - med['off']:.3f}; trust tests "
          f"themselves: {rev} {t[rev]:.3f}, now {t['now']:.3f} ms/peer-scan (now / {rev} "
          f"{t['now'] / t[rev]:.3f}); load average {load_average()} at the end")


def batches(path: Path, sizes: list[int], n: int, scans: int, repeats: int, lie: str | None,
            kind: str) -> None:
    """``--batches``: trust on, host-batched, at most each of ``sizes`` rounds a call,
    alternated; the trust tests' thread CPU split by round, and the fixed / variable fit."""
    spent: dict[int, list[float]] = {}  # round -> [thread seconds, calls, rounds]

    def by_round(calls):
        t0 = time.thread_time()
        try:
            return trust_batch.weigh_together(calls)
        finally:
            v = spent.setdefault(calls[0][2], [0.0, 0, 0])
            v[0] += time.thread_time() - t0
            v[1] += 1
            v[2] += len(calls)

    per: dict[tuple[int, int], list[float]] = {}
    print("| batch | rep | CPU ms/peer-scan | trust tests | round | us a round | us a call "
          "| calls |\n|---:|---:|---:|---:|---:|---:|---:|---:|", flush=True)
    global weigh_together
    saved = weigh_together
    try:
        for rep in range(repeats):
            for b in (sizes if rep % 2 == 0 else sizes[::-1]):
                spent.clear()
                weigh_together = by_round  # what one_run chunks (_chunked looks it up)
                try:
                    v, _, _ = one_run(path, True, n, scans, lie, kind=kind, batch=b)
                finally:
                    weigh_together = saved
                for rnd, (t, calls, rounds) in sorted(spent.items()):
                    per.setdefault((b, rnd), []).append(t * 1e6 / rounds)
                    print(f"| {b} | {rep + 1} | {v:.3f} | {TESTS[-1]:.3f} | {rnd} | "
                          f"{t * 1e6 / rounds:.1f} | {t * 1e6 / calls:.0f} | {calls} |",
                          flush=True)
    finally:
        weigh_together = saved
        batching.weigh_together = saved  # one_run put back the wrapper it found
    print()
    for rnd in sorted({r for _, r in per}):
        xs = [1.0 / b for b in sizes if (b, rnd) in per]
        ys = [statistics.median(per[(b, rnd)]) for b in sizes if (b, rnd) in per]
        if len(xs) < 2:
            continue
        fixed, variable = np.polyfit(xs, ys, 1)
        print(f"round {rnd}: medians " + ", ".join(f"{b} {y:.1f}" for b, y in
                                                   zip(sizes, ys, strict=False))
              + f" us a round; fit: {variable:.1f} us a round + {fixed:.0f} us a call")
    print(f"load average {load_average()} at the end")


def young(path: Path, size: int, n: int, scans: int, repeats: int, lie: str | None,
          kind: str, batch: int | None) -> None:
    """``--young N``: CPython's generation-0 threshold and ``size``, alternated."""
    base = gc.get_threshold()
    spent = [0.0, 0, 0.0]  # seconds in collections, collections, the current one's start

    def count(phase: str, info: dict) -> None:
        if phase == "start":
            spent[2] = time.thread_time()
        else:
            spent[0] += time.thread_time() - spent[2]
            spent[1] += 1

    ms: dict[int, list[float]] = {base[0]: [], size: []}
    in_gc: dict[int, list[float]] = {base[0]: [], size: []}
    print("| gen-0 threshold | rep | CPU ms/peer-scan | in collections | collections | RSS MiB |"
          "\n|---:|---:|---:|---:|---:|---:|", flush=True)
    gc.callbacks.append(count)
    try:
        for rep in range(repeats):
            for t0 in ((base[0], size) if rep % 2 == 0 else (size, base[0])):
                gc.collect()
                gc.freeze()
                gc.set_threshold(t0, *base[1:])
                spent[:2] = [0.0, 0]
                try:
                    v, _, _ = one_run(path, True, n, scans, lie, kind=kind, batch=batch)
                finally:
                    gc.set_threshold(*base)
                    gc.unfreeze()
                g = spent[0] * 1e3 / n / scans
                ms[t0].append(v)
                in_gc[t0].append(g)
                print(f"| {t0} | {rep + 1} | {v:.3f} | {g:.4f} | {spent[1]} | {_rss_mib():.0f} |",
                      flush=True)
    finally:
        gc.callbacks.remove(count)
    a, b = base[0], size
    med = {k: statistics.median(v) for k, v in ms.items()}
    g = {k: statistics.median(v) for k, v in in_gc.items()}
    print(f"\nmedians: {a} {med[a]:.3f} ms/peer-scan ({g[a]:.4f} in collections), {b} "
          f"{med[b]:.3f} ({g[b]:.4f}); {b} / {a} {med[b] / med[a]:.3f}, pairs "
          f"{[round(y / x, 3) for x, y in zip(ms[a], ms[b], strict=True)]}; load average "
          f"{load_average()} at the end")


def _rss_mib() -> float:
    """This process's resident memory (Linux ``/proc/self/statm``; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096 / 2**20
    except OSError:
        return float("nan")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--scans", type=int, default=40)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--filter", default="lmb", choices=("lmb", "gmphd"),
                   help="the peers' kind (network.filter)")
    p.add_argument("--every-round", action="store_true",
                   help="also trust on with TrustConfig.test_once off (every round tested "
                        "in full, as before 2026-12-05)")
    p.add_argument("--ops", action="store_true",
                   help="split the host-batched trust tests by stacked request kind")
    p.add_argument("--lie", default=None,
                   help="a lying peer (fusion.lie, e.g. p02:biased): the defence's decisions")
    p.add_argument("--against", metavar="REV", default=None,
                   help="only trust off, REV's host-batched stacked requests and today's, "
                        "alternated in this process")
    p.add_argument("--batch", type=int, default=None, metavar="N",
                   help="at most N rounds tested together a call (a host of 25 peers: "
                        "12-15 a pass); default all of a pass")
    p.add_argument("--batches", default=None, metavar="N,M,..",
                   help="only trust on, host-batched at most N, M, .. rounds a call, "
                        "alternated: the trust tests split by round, fixed and per round")
    p.add_argument("--young", type=int, default=None, metavar="N",
                   help="only trust on, CPython's generation-0 collection threshold and N "
                        "alternated (a host's peers.host.YOUNG_GC)")
    args = p.parse_args()
    if args.batch is not None and args.batch < 1:
        p.error("--batch must be at least 1")
    if args.young is not None and args.young < 1:
        p.error("--young must be at least 1")
    n, scans, kind = args.peers, args.scans, args.filter
    sizes = None
    if args.batches is not None:
        try:
            sizes = [int(x) for x in args.batches.split(",")]
        except ValueError:
            sizes = []
        if not sizes or min(sizes) < 1:
            p.error("--batches takes rounds a call, e.g. 12,25,50 (each at least 1)")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, 4, scans, rounds=2, speed=10.0))
        if sizes:
            print(f"## twin of {n} {kind} peers, degree 4, 2 rounds, {scans} scans, trust on, "
                  f"host-batched at most {args.batches} rounds a call; load average "
                  f"{load_average()}")
            batches(path, sizes, n, scans, args.repeats, args.lie, kind)
            return
        if args.young:
            print(f"## twin of {n} {kind} peers, degree 4, 2 rounds, {scans} scans, trust on, "
                  f"host-batched: generation-0 threshold {gc.get_threshold()[0]} and "
                  f"{args.young}; load average {load_average()}")
            young(path, args.young, n, scans, args.repeats, args.lie, kind, args.batch)
            return
        if args.against:
            try:
                subprocess.run(["git", "-C", str(Path(__file__).resolve().parents[1]),
                                "rev-parse", "--verify", f"{args.against}^{{commit}}"],
                               capture_output=True, check=True)
            except subprocess.CalledProcessError:
                p.error(f"--against {args.against}: not a revision of this repository")
            print(f"## twin of {n} {kind} peers, degree 4, 2 rounds, {scans} scans: trust "
                  f"off, {args.against}'s stacked trust requests and today's"
                  + (f", at most {args.batch} rounds a call" if args.batch else "")
                  + f"; load average {load_average()}")
            against(path, args.against, n, scans, args.repeats, args.lie, kind, args.batch)
            return
        ms: dict[str, list[float]] = {"off": [], "on (per peer)": [], "on (host-batched)": []}
        print(f"## twin of {n} {kind} peers, degree 4, 2 rounds, {scans} scans"
              + (f", at most {args.batch} rounds a call" if args.batch else ""))
        print("| run | rep | CPU ms/peer-scan | of which trust tests |\n|---|---:|---:|---:|",
              flush=True)
        tests: dict[str, list[float]] = {}
        for rep in range(args.repeats):
            v, _, _ = one_run(path, False, n, scans, args.lie, kind=kind, batch=args.batch)
            ms["off"].append(v)
            print(f"| off | {rep + 1} | {v:.2f} | |", flush=True)
            v, tracks_one, sum_one = one_run(path, True, n, scans, args.lie, together=False,
                                             kind=kind)
            ms["on (per peer)"].append(v)
            tests.setdefault("per peer", []).append(TESTS[-1])
            print(f"| on (per peer) | {rep + 1} | {v:.2f} | {TESTS[-1]:.3f} |", flush=True)
            saved = _count_ops() if args.ops else None
            try:
                v, tracks_new, sum_new = one_run(path, True, n, scans, args.lie, kind=kind,
                                                 batch=args.batch)
            finally:
                if saved is not None:
                    trust_batch.TOGETHER.update(saved)
            ms["on (host-batched)"].append(v)
            tests.setdefault("host-batched", []).append(TESTS[-1])
            print(f"| on (host-batched) | {rep + 1} | {v:.2f} | {TESTS[-1]:.3f} |",
                  flush=True)
            if args.ops:
                print_ops(n, scans)
            print(f"per peer vs host-batched: fused states identical: "
                  f"{same_tracks(tracks_one, tracks_new)}, trust summaries identical: "
                  f"{sum_one == sum_new} "
                  f"({sum(len(v['changes']) for v in sum_new.values())} state changes)",
                  flush=True)
            if args.every_round:
                v, _, sum_all = one_run(path, True, n, scans, args.lie, once=False, kind=kind,
                                        batch=args.batch)
                ms.setdefault("on (every round)", []).append(v)
                print(f"| on (every round) | {rep + 1} | {v:.2f} | {TESTS[-1]:.3f} |",
                      flush=True)
                print(f"every round vs host-batched: trust summaries identical: "
                      f"{sum_all == sum_new} "
                      f"({sum(len(v['changes']) for v in sum_all.values())} state changes)",
                      flush=True)
    med = {k: statistics.median(v) for k, v in ms.items()}
    off = med["off"]
    print("\n" + ", ".join(f"{k} {v:.2f}" for k, v in med.items()) + " ms/peer-scan (medians)")
    print(f"on (per peer) / off: {med['on (per peer)'] / off:.2f}, "
          f"on (host-batched) / off: {med['on (host-batched)'] / off:.2f}, "
          f"host-batched / per peer: {med['on (host-batched)'] / med['on (per peer)']:.2f}; "
          f"trust ms/peer-scan: per peer {med['on (per peer)'] - off:.2f}, "
          f"host-batched {med['on (host-batched)'] - off:.2f}"
          + (f", on (every round) / off: {med['on (every round)'] / off:.2f}"
             if args.every_round else ""))
    t = {k: statistics.median(v) for k, v in tests.items()}
    print(f"the trust tests themselves (Trust.weigh / weigh_together), ms/peer-scan (medians): "
          f"per peer {t['per peer']:.3f}, host-batched {t['host-batched']:.3f} "
          f"(host-batched / per peer {t['host-batched'] / t['per peer']:.2f})")


if __name__ == "__main__":
    main()
