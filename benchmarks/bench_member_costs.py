"""What a member's size costs its honest neighbours, as real processes (issue 36's targets).

Each case runs a clean network and the same network with padding members back to back (the
order alternating from repeat to repeat), world and peers as OS processes on loopback, births
at the truth, Rerun off. A padding member (``tests/padding_member.py``) sends its real estimate
padded with weight-1e-4 components up to the codec's 2,000-component limit (240 kB at d = 4),
``--copies`` times per scan and round (1: one estimate a scan, as an honest peer; 4: the whole
message rate the receivers' buckets allow):

- ``padding``: seed 000 (3 peers, 100 scans at 10 scans/s), s2 padding, ``fusion.trust`` off
  and on (T1);
- ``mesh``: a secure mesh of 8 (``--secure``: mutual TLS, every message signed; seed 000's
  targets seen by 8 linear sensors, full mesh, 60 scans at 10 scans/s), two (s2, s5) and then
  six (s2-s7) members padding with their own keys (T2).

Prints, per honest peer: scans handled / scans, scans fused (tracks published), deadline
fusions, p99 scan -> fused tracks (ms; the target: under one scan interval), fused OSPA (m)
and its ratio to the clean run's (target <= 1.1), peak RSS (MB) and its ratio (target <= 1.2),
process CPU per scan (ms: the honest cost measure on a shared machine) and its ratio, what the
budget refused (``bytes``) or reduced; with the 1-minute load average before and after each
run (judge the p99 against it).

    python benchmarks/bench_member_costs.py [--case padding|mesh|all] [--repeat 1]
                                            [--copies 1] [--scans N]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.security import make_keys  # noqa: E402
from sensornet.sim.run.launcher import read_summaries, wait_run  # noqa: E402
from sensornet.sim.scenario import load_scenario, parse_overrides  # noqa: E402

from tests.padding_member import PAD, start_padded_run  # noqa: E402

NETWORK = "benchcosts"
MESH_EXTRA = [(-800.0, 1000.0), (0.0, -1000.0), (0.0, 1000.0), (-1000.0, 0.0), (800.0, 1000.0)]
"""Positions of the mesh's sensors s4-s8 (linear sensors: the position does not change what
they see; seed 000's s1-s3 as they are)."""
MESH_LIARS = {"two": ("s2", "s5"), "six": ("s2", "s3", "s4", "s5", "s6", "s7")}


def mesh_source(folder: Path) -> Path:
    """Seed 000's scenario file with five more linear sensors like its three (8 in all)."""
    text = (Path(__file__).resolve().parents[1] / "sim/scenarios/seed000.toml").read_text()
    extra = "".join(
        f'\n[[sensors]]\nname = "s{i}"\nkind = "linear"\nposition = [{x}, {y}]\n'
        f"sigma_r = 20.0\ndetection_probability = 0.99\nclutter_rate = 10\n"
        for i, (x, y) in enumerate(MESH_EXTRA, start=4))
    marker = "# A radar instead"
    path = folder / "mesh8.toml"
    path.write_text(text.replace(marker, extra + "\n" + marker, 1).replace(
        'name = "seed000"', 'name = "mesh8"', 1))
    return path


def one_run(out: Path, source: str, sets: list[str], liars: dict, keys: Path | None,
            timeout: float, nice: int = 0) -> dict:
    """One run; its summaries, exit codes and the load average before and after."""
    scn = load_scenario(source, overrides=parse_overrides(sets))
    load0 = os.getloadavg()[0]
    handle = start_padded_run(scn, source, out, liars, network=NETWORK, overrides=sets,
                              rerun=False, secure=keys, nice=nice)
    try:
        codes = wait_run(handle, timeout=timeout)
    finally:
        handle.stop_all()
    return {"summaries": read_summaries(out, scn.sensor_names), "codes": codes,
            "load": (load0, os.getloadavg()[0]), "scans": scn.num_scans,
            "interval_ms": 1e3 * scn.scan_period / scn.network.speed}


def peer_row(s: dict, c: dict, run: dict) -> dict:
    """The numbers of one honest peer ``s`` against its clean twin ``c``."""
    def cpu(x: dict) -> float:
        return 1e3 * x["cpu_s_running"] / max(1, x["scans"])
    b = s.get("budget") or {}
    return {"scans": s["scans"], "fused": len(s.get("latency_ms_samples") or []),
            "deadline": s["stats"]["deadline_fusions"], "p99": s["latency_ms_p99"] or 0.0,
            "ospa": s["mean_ospa_fused"], "ospa_ratio": s["mean_ospa_fused"]
            / c["mean_ospa_fused"], "rss": s["max_rss_mb"],
            "rss_ratio": s["max_rss_mb"] / c["max_rss_mb"], "cpu": cpu(s),
            "cpu_ratio": cpu(s) / max(cpu(c), 1e-9),
            "refused": sum((b.get("refused") or {}).values()),
            "reduced": sum((b.get("reduced") or {}).values()),
            "met": (s["scans"] == run["scans"] and (s["latency_ms_p99"] or 0) < run["interval_ms"]
                    and s["mean_ospa_fused"] <= 1.1 * c["mean_ospa_fused"]
                    and s["max_rss_mb"] <= 1.2 * c["max_rss_mb"])}


def cpu_parts(summaries: list[dict]) -> dict[str, float]:
    """Mean process CPU per scan (ms) by part (``cpu_ms_breakdown``: Zenoh's threads as
    ``transport``, the core's steps by channel, publishing, the loop) over ``summaries``."""
    parts: dict[str, float] = {}
    for s in summaries:
        for k, ms in (s.get("cpu_ms_breakdown") or {}).items():
            parts[k] = parts.get(k, 0.0) + ms / max(1, s["scans"]) / len(summaries)
    return parts


SUMMARY: list[str] = []
"""One line per pair, the honest peers pooled (printed last: the table of docs/security.md)."""


def summarise(label: str, clean: dict, attacked: dict, honest: list[str]) -> str:
    """The pair's honest peers pooled: fewest scans handled, most deadline fusions, worst p99
    (clean's beside it), worst OSPA and RSS ratios, mean CPU per scan ratio, the load."""
    rows = [peer_row(attacked["summaries"][n], clean["summaries"][n], attacked)
            for n in honest]
    cp99 = max(clean["summaries"][n]["latency_ms_p99"] or 0.0 for n in honest)
    cdl = max(clean["summaries"][n]["stats"]["deadline_fusions"] for n in honest)
    return (f"| {label} | {min(r['scans'] for r in rows)} / {attacked['scans']} | "
            f"{max(r['deadline'] for r in rows)} ({cdl}) | "
            f"{max(r['p99'] for r in rows):.0f} ({cp99:.0f}) | "
            f"{max(r['ospa_ratio'] for r in rows):.2f} | {max(r['rss_ratio'] for r in rows):.2f} "
            f"| {sum(r['cpu_ratio'] for r in rows) / len(rows):.2f} | "
            f"{sum(r['refused'] for r in rows) / len(rows):.0f} / "
            f"{sum(r['reduced'] for r in rows) / len(rows):.0f} | "
            f"{max(clean['load'] + attacked['load']):.0f} |")


def print_pair(label: str, clean: dict, attacked: dict, honest: list[str]) -> bool:
    """Rows for the honest peers of one clean/attacked pair (each peer's clean row, then its
    attacked one); True if every target was met."""
    ok = True
    SUMMARY.append(summarise(label, clean, attacked, honest))
    for name in honest:
        c, s = clean["summaries"][name], attacked["summaries"][name]
        for case, run, x in (("clean", clean, c), ("attacked", attacked, s)):
            r = peer_row(x, c, run)
            ok &= r["met"]
            print(f"| {label} | {case} | {name} | {r['scans']} / {run['scans']} | {r['fused']} "
                  f"| {r['deadline']} | {r['p99']:.0f} | {r['ospa']:.1f} ({r['ospa_ratio']:.2f}) "
                  f"| {r['rss']:.0f} ({r['rss_ratio']:.2f}) | {r['cpu']:.1f} "
                  f"({r['cpu_ratio']:.2f}) | {r['refused']} / {r['reduced']} | "
                  f"{run['load'][0]:.1f}-{run['load'][1]:.1f} | "
                  f"{'met' if r['met'] else 'MISSED'} |")
    parts = {case: cpu_parts([run["summaries"][n] for n in honest])
             for case, run in (("clean", clean), ("attacked", attacked))}
    print("  CPU ms/scan by part, honest peers, clean -> attacked: " + ", ".join(
        f"{k} {parts['clean'].get(k, 0.0):.2f} -> {v:.2f}" for k, v in parts["attacked"].items()
        if abs(v - parts["clean"].get(k, 0.0)) >= 0.05))
    liars = [n for n in attacked["summaries"] if n not in honest]
    print("  padding members (their own cost): " + ", ".join(
        f"{n} CPU {1e3 * x['cpu_s_running'] / max(1, x['scans']):.1f} ms/scan "
        f"(clean {1e3 * c['cpu_s_running'] / max(1, c['scans']):.1f}), estimates out "
        f"{x['stats'].get('estimates_out', 0)}"
        for n in liars for x, c in [(attacked["summaries"][n], clean["summaries"][n])]))
    bad = {k: v for run in (clean, attacked) for k, v in run["codes"].items() if v != 0}
    if bad:
        print(f"  (non-zero exits: {bad})")
    return ok


HEADER = ("| case | run | peer | scans handled | fused | deadline fusions | p99 ms | "
          "fused OSPA m (/ clean) | peak RSS MB (/ clean) | CPU ms/scan (/ clean) | "
          "refused bytes / reduced | load 1-min before-after | targets |\n"
          "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---|")


def pair(tmp: Path, tag: str, i: int, source: str, sets: list[str], liars: dict,
         keys: Path | None, timeout: float, nice: int = 0) -> tuple[dict, dict]:
    """Clean and attacked runs back to back, the order alternating with ``i``."""
    runs = {}
    for case in (("clean", "attacked") if i % 2 == 0 else ("attacked", "clean")):
        runs[case] = one_run(tmp / f"{tag}-{case}-{i}", source, sets,
                             liars if case == "attacked" else {}, keys, timeout, nice)
    return runs["clean"], runs["attacked"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=("padding", "mesh", "all"), default="all")
    ap.add_argument("--repeat", type=int, default=1, help="clean/attacked pairs per cell")
    ap.add_argument("--copies", type=int, default=1,
                    help="each padded estimate sent this many times (4: the bucket's rate)")
    ap.add_argument("--pad", type=int, default=PAD, help="components per padded estimate")
    ap.add_argument("--scans", type=int, default=0, help="default 100 (padding), 60 (mesh)")
    ap.add_argument("--trust", choices=("off", "on", "both"), default="both",
                    help="fusion.trust in the padding case")
    ap.add_argument("--liars", choices=(*MESH_LIARS, "both"), default="both",
                    help="mesh case: two or six padding members, or both")
    ap.add_argument("--nice", type=int, default=0,
                    help="the padding members' nice value (10: their own extra work yields "
                    "to the honest peers, as on machines of their own)")
    ap.add_argument("--keep", type=Path, help="keep the runs' folders here (default: a "
                    "temporary folder, removed)")
    a = ap.parse_args(argv)
    ok = True
    x = (f" x{a.copies}" if a.copies != 1 else "") + (f", nice {a.nice}" if a.nice else "")
    print(f"padding to {a.pad} components, {a.copies} cop{'y' if a.copies == 1 else 'ies'} "
          f"per scan and round; {os.cpu_count()} CPUs")
    print(HEADER)
    with tempfile.TemporaryDirectory() as td:
        tmp = a.keep or Path(td)
        tmp.mkdir(parents=True, exist_ok=True)
        if a.case in ("padding", "all"):
            scans = a.scans or 100
            for trust in {"off": (False,), "on": (True,), "both": (False, True)}[a.trust]:
                sets = ["birth.model=truth", f"scenario.num_scans={scans}",
                        "network.speed=10", f"fusion.trust={str(trust).lower()}"]
                for i in range(a.repeat):
                    clean, att = pair(tmp, f"pad-{trust}", i, "seed000", sets,
                                      {"s2": (a.pad, a.copies)}, None, scans / 10 + 180,
                                      a.nice)
                    ok &= print_pair(f"seed 000, trust {'on' if trust else 'off'}, s2 pads{x}",
                                     clean, att, ["s1", "s3"])
        if a.case in ("mesh", "all"):
            scans = a.scans or 60
            source = str(mesh_source(tmp))
            keys = tmp / "keys"
            make_keys(NETWORK, ["world", *(f"s{i}" for i in range(1, 9))], keys)
            sets = ["birth.model=truth", f"scenario.num_scans={scans}", "network.speed=10"]
            for label, names in MESH_LIARS.items():
                if a.liars not in ("both", label):
                    continue
                liars = {n: (a.pad, a.copies) for n in names}
                honest = [f"s{i}" for i in range(1, 9) if f"s{i}" not in names]
                for i in range(a.repeat):
                    clean, att = pair(tmp, f"mesh-{label}", i, source, sets, liars, keys,
                                      scans / 10 + 240, a.nice)
                    ok &= print_pair(f"secure mesh of 8, {label} pad{x}", clean, att, honest)
    print("\nhonest peers pooled (worst peer; in brackets the clean run's):")
    print("| case | scans handled | deadline fusions | p99 ms | fused OSPA / clean | "
          "peak RSS / clean | CPU per scan / clean | refused (bytes) / reduced per peer | "
          "load 1-min max |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(SUMMARY))
    print("all targets met" if ok else "some target missed (MISSED rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
