"""What the defence against lying neighbours (``fusion.trust``) costs a peer-scan, old and new.

The twin (``sim.run.twin``, a virtual clock, no transport; the peers of one host: a shared
decode, batched rounds) of ``n`` LMB peers on a circulant graph of degree 4, 2 consensus
rounds, run three ways in ONE process, interleaved ``--repeats`` times: trust off, trust on
with the trust checks of ``benchmarks/trust_before.py`` (the module before the speed-up,
patched into the trust modules: one ``offset_information``, ``add_offset`` and ``gls_offset`` per
neighbour, the unmatched weights made again by the withheld-target test) and trust on as
it is. Prints per run the process CPU per peer-scan, then the medians and the ratios on /
off; and whether the old and new runs published the same fused states to the bit and ended
with the same trust states, scores and state changes (the speed-up must change no
decision). Both trust-on runs take :attr:`TrustConfig.test_once` at its default (on: a full
test once a scan where round 1 found nothing); ``--every-round`` adds a run with it off.

    python benchmarks/bench_trust_cost.py                      # 50 peers, 40 scans, 2 repeats
    python benchmarks/bench_trust_cost.py --peers 20 --scans 20 --repeats 1
    python benchmarks/bench_trust_cost.py --peers 20 --scans 30 --repeats 1 --lie p02:biased
    python benchmarks/bench_trust_cost.py --every-round   # also TrustConfig.test_once off
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if not __package__:  # `python benchmarks/bench_trust_cost.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers import trust, trust_checks, trust_record, trust_repair, trust_scan
from sensornet.peers.host import SharedDecode
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario

from benchmarks import trust_before
from benchmarks.bench_network import scenario_text

MODULES = (trust, trust_scan, trust_record, trust_repair)
"""The modules that import the trust checks by name (patched for the 'old' runs)."""


@contextlib.contextmanager
def old_checks():
    """The trust modules with ``benchmarks/trust_before.py``'s functions in place of
    :mod:`peers.trust_checks`' (every name they imported from it)."""
    saved = []
    for mod in MODULES:
        for name, value in vars(mod).items():
            if callable(value) and getattr(trust_checks, name, None) is value \
                    and hasattr(trust_before, name):
                saved.append((mod, name, value))
    saved.append((trust_scan, "offset_information_many", trust_scan.offset_information_many))
    saved.append((trust_scan, "add_offsets", trust_scan.add_offsets))
    saved.append((trust_scan, "gls_offsets", trust_scan.gls_offsets))
    old = {name: getattr(trust_before, name) for _, name, _ in saved if name in vars(
        trust_before)}
    old["neighbour_statistics"] = _old_statistics
    old["offset_information_many"] = _old_offsets
    old["add_offsets"] = _old_add_offsets
    old["gls_offsets"] = lambda infos: [trust_before.gls_offset([i]) for i in infos]
    try:
        for mod, name, _ in saved:
            setattr(mod, name, old[name])
        yield
    finally:
        for mod, name, value in saved:
            setattr(mod, name, value)


def _old_statistics(cfg, own, inputs, weights, quarantined, pos=(0, 2), keep=None):
    """The old ``neighbour_statistics`` (which kept nothing for the withheld-target test)."""
    return trust_before.neighbour_statistics(cfg, own, inputs, weights, quarantined, pos)


def _old_offsets(ref, mixes, pos, min_weight, gate, chi2=None):
    """The old per-neighbour ``offset_information`` calls."""
    return [trust_before.offset_information(ref, m, pos, min_weight, gate, chi2)
            for m in mixes]


def _old_add_offsets(cfg, recs, infos):
    """The old per-neighbour ``add_offset`` calls (its ``offset_chi2`` the old one)."""
    return [trust_record.add_offset(cfg, rec, info) for rec, info in
            zip(recs, infos, strict=True)]


def one_run(path: Path, trust_on: bool, n: int, scans: int, lie: str | None = None,
            once: bool | None = None):
    """One twin run (``lie``: ``fusion.lie``, e.g. ``p02:biased``; ``once``: the peers'
    :attr:`TrustConfig.test_once`, None: the default): CPU ms per peer-scan, the fused
    states and the trust summaries."""
    over = {"network.filter": "lmb", "fusion.trust": trust_on}
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
    t0 = time.process_time()
    result = run_twin(scn, 0, peers=peers, batch=True)
    ms = (time.process_time() - t0) * 1e3 / n / scans
    summaries = {}
    for q, core in peers.items():
        tr = core.consensus.trust
        if tr is not None:
            tr.finish()
            summaries[q] = tr.summary()
    return ms, result.tracks, summaries


def same_tracks(a: dict, b: dict) -> bool:
    """Whether two runs published the same fused states, bit for bit."""
    return a.keys() == b.keys() and all(
        a[q].keys() == b[q].keys() and all(np.array_equal(a[q][k], b[q][k]) for k in a[q])
        for q in a)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--scans", type=int, default=40)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--every-round", action="store_true",
                   help="also trust on with TrustConfig.test_once off (every round tested "
                        "in full, as before 2026-12-05)")
    p.add_argument("--lie", default=None,
                   help="a lying peer (fusion.lie, e.g. p02:biased): the defence's decisions")
    args = p.parse_args()
    n, scans = args.peers, args.scans
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(n, 4, scans, rounds=2, speed=10.0))
        ms: dict[str, list[float]] = {"off": [], "on (old)": [], "on (new)": []}
        print(f"## twin of {n} LMB peers, degree 4, 2 rounds, {scans} scans")
        print("| run | rep | CPU ms/peer-scan |\n|---|---:|---:|", flush=True)
        for rep in range(args.repeats):
            v, _, _ = one_run(path, False, n, scans, args.lie)
            ms["off"].append(v)
            print(f"| off | {rep + 1} | {v:.2f} |", flush=True)
            with old_checks():
                v, tracks_old, sum_old = one_run(path, True, n, scans, args.lie)
            ms["on (old)"].append(v)
            print(f"| on (old) | {rep + 1} | {v:.2f} |", flush=True)
            v, tracks_new, sum_new = one_run(path, True, n, scans, args.lie)
            ms["on (new)"].append(v)
            print(f"| on (new) | {rep + 1} | {v:.2f} |", flush=True)
            print(f"old vs new: fused states identical: {same_tracks(tracks_old, tracks_new)}, "
                  f"trust summaries identical: {sum_old == sum_new} "
                  f"({sum(len(v['changes']) for v in sum_new.values())} state changes)",
                  flush=True)
            if args.every_round:
                v, _, sum_all = one_run(path, True, n, scans, args.lie, once=False)
                ms.setdefault("on (every round)", []).append(v)
                print(f"| on (every round) | {rep + 1} | {v:.2f} |", flush=True)
                print(f"every round vs new: trust summaries identical: {sum_all == sum_new} "
                      f"({sum(len(v['changes']) for v in sum_all.values())} state changes)",
                      flush=True)
    med = {k: statistics.median(v) for k, v in ms.items()}
    print("\n" + ", ".join(f"{k} {v:.2f}" for k, v in med.items()) + " ms/peer-scan (medians)")
    print(f"on (old) / off: {med['on (old)'] / med['off']:.2f}, "
          f"on (new) / off: {med['on (new)'] / med['off']:.2f}, "
          f"new / old: {med['on (new)'] / med['on (old)']:.2f}"
          + (f", on (every round) / off: {med['on (every round)'] / med['off']:.2f}"
             if args.every_round else ""))


if __name__ == "__main__":
    main()
