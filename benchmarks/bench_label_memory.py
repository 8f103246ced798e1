"""The GM-PHD peers' label bookkeeping against a git revision's, on the 50-peer twin.

Runs the twin of ``bench_fifty.py --twin`` (50 peers, degree 4, L = 2, GM-PHD, the host's
shared decode and batched fusions) alternately with this tree's re-identification memory and
track confirmation (``tracking.reidentify.Reidentification``, ``tracking.label_confirmation
.Confirmation``) and with ``--against REV``'s methods of both classes swapped in, the world's
run generated once outside the timed part. Prints each pair's CPU ms per peer-scan, the
medians, the pairs' ratios and both runs' mean fused OSPA (equal: the same answers). One
process, so the two sides share the interpreter, the imports and the machine's minutes.

    python benchmarks/bench_label_memory.py --against 61ec4c1
    python benchmarks/bench_label_memory.py --against 61ec4c1 --set fusion.trust=false
    python benchmarks/bench_label_memory.py --against 61ec4c1 --pairs 6 --scans 40
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

if not __package__:  # `python benchmarks/bench_label_memory.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import sensornet.tracking.label_confirmation as lc
import sensornet.tracking.reidentify as reid
from sensornet.peers.host import SharedDecode
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.sim.world import generate_run

from benchmarks.bench_network import load_average, scenario_text

ROOT = Path(__file__).resolve().parents[1]
SWAPPED = {reid.Reidentification: ("tracking/reidentify.py", "Reidentification"),
           lc.Confirmation: ("tracking/label_confirmation.py", "Confirmation")}
"""Each class whose methods are swapped: the file and class name at the revision."""


def module_at(rev: str, path: str) -> types.ModuleType:
    """``path`` at git revision ``rev``, imported under another name (the rest of the package
    as now)."""
    text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"],
                          capture_output=True, text=True, check=True).stdout
    name = f"_at_rev_{Path(path).stem}"
    module = types.ModuleType(name)
    sys.modules[name] = module  # dataclasses look their module up
    exec(compile(text, f"{rev}:{path}", "exec"), module.__dict__)
    return module


def method_sets(rev: str) -> dict[str, dict[type, dict[str, object]]]:
    """``{"now": ..., "rev": ...}``: per class, its functions defined in the class body."""
    now = {c: {k: v for k, v in vars(c).items() if isinstance(v, types.FunctionType)}
           for c in SWAPPED}
    old = {}
    for c, (path, name) in SWAPPED.items():
        oc = getattr(module_at(rev, path), name)
        old[c] = {k: v for k, v in vars(oc).items() if isinstance(v, types.FunctionType)}
    return {"now": now, "rev": old}


def use(methods: dict[type, dict[str, object]], other: dict[type, dict[str, object]]) -> None:
    """Set ``methods`` on their classes; the other side's methods they lack removed."""
    for c, fs in methods.items():
        for k in other[c]:
            if k not in fs and k in vars(c):
                delattr(c, k)
        for k, f in fs.items():
            setattr(c, k, f)


def add_arguments(p: argparse.ArgumentParser, pairs: int) -> None:
    """The options both label benchmarks take (this one and bench_label_support.py)."""
    p.add_argument("--against", metavar="REV", required=True, help="the git revision to compare")
    p.add_argument("--pairs", type=int, default=pairs, help=f"alternated pairs (default {pairs})")
    p.add_argument("--scans", type=int, default=100, help="scans per run (default 100)")
    p.add_argument("--peers", type=int, default=50)
    p.add_argument("--degree", type=int, default=4)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="a scenario override (repeatable), e.g. fusion.trust=false")


def twin_world(args: argparse.Namespace, kind: str) -> tuple[object, object]:
    """The 50-peer twin's scenario (degree ``--degree``, L = 2, ``kind`` peers) and its run 0,
    generated once outside the timed part."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(args.peers, args.degree, args.scans, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides=parse_overrides(
            [f"network.filter={kind}", *args.sets]))
    return scn, generate_run(scn, 0)


def alternate(args: argparse.Namespace, scn, data, sides: dict,
              tables: bool = False) -> tuple[dict[str, list[float]], dict[str, float], dict]:
    """``--pairs`` twin runs of each side (REV's methods swapped in, then this tree's, the order
    alternated a pair), each pair's CPU ms per peer-scan printed: ``(ms, mean fused OSPA, every
    peer's pickled results tables if tables)`` per side."""
    n = args.peers
    ms: dict[str, list[float]] = {"rev": [], "now": []}
    ospa: dict[str, float] = {}
    kept: dict[str, bytes] = {}
    try:
        for rep in range(args.pairs):
            for side in ("rev", "now") if rep % 2 == 0 else ("now", "rev"):
                use(sides[side], sides["now" if side == "rev" else "rev"])
                peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
                shared = SharedDecode()
                for core in peers.values():
                    core.decode = shared
                t0 = time.process_time()
                result = run_twin(scn, 0, peers=peers, batch=True, data=data)
                ms[side].append((time.process_time() - t0) * 1e3 / n / args.scans)
                ospa[side] = statistics.fmean(result.mean_ospa(q) for q in scn.sensor_names)
                if tables:
                    kept[side] = pickle.dumps([core.scorer.results.table(q)
                                               for q, core in sorted(peers.items())])
            print(f"pair {rep + 1}: {args.against} {ms['rev'][-1]:.3f}, now {ms['now'][-1]:.3f} "
                  f"ms/peer-scan (load {os.getloadavg()[0]:.1f})", flush=True)
    finally:
        use(sides["now"], sides["rev"])
    return ms, ospa, kept


def summary(args: argparse.Namespace, ms: dict[str, list[float]], ospa: dict[str, float]) -> str:
    """The medians, the pairs' ratios and both sides' mean fused OSPA in one line."""
    a, b = statistics.median(ms["rev"]), statistics.median(ms["now"])
    ratios = ", ".join(f"{y / x:.3f}" for x, y in zip(ms["rev"], ms["now"], strict=True))
    return (f"\nmedian {args.against} {a:.3f}, now {b:.3f} ms/peer-scan: now/{args.against} "
            f"{b / a:.3f} (pairs {ratios}); fused OSPA {ospa['rev']:.6f} / {ospa['now']:.6f}")


def run_against(argv: list[str] | None, doc: str, sets_of, kind: str, what: str, pairs: int,
                tables: bool = False) -> tuple[argparse.Namespace, str, dict]:
    """The command of a bench of this kind: its arguments (``doc``'s first line the help),
    ``sets_of(REV)``'s method sets (an unknown REV a one-line error), the ``kind`` twin world,
    a header naming ``what`` is compared, the alternated pairs; the summary line and the
    results tables (``tables``)."""
    p = argparse.ArgumentParser(description=doc.split("\n")[0])
    add_arguments(p, pairs=pairs)
    args = p.parse_args(argv)
    try:
        sides = sets_of(args.against)
    except subprocess.CalledProcessError as exc:
        p.error(f"--against {args.against}: {exc.stderr.strip() or 'not a revision'}")
    scn, data = twin_world(args, kind)
    print(f"## {what}, this tree against {args.against}: {args.peers} {kind} peers, degree "
          f"{args.degree}, 2 rounds, {args.scans} scans"
          f"{''.join(' --set ' + x for x in args.sets)}; load average {load_average()}\n")
    ms, ospa, got = alternate(args, scn, data, sides, tables=tables)
    return args, summary(args, ms, ospa), got


def main(argv: list[str] | None = None) -> int:
    _, line, _ = run_against(argv, __doc__, method_sets, "gmphd",
                             "label memory and confirmation", pairs=4)
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
