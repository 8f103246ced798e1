"""What a finished run left: the peers' summary files, the merged Rerun recording, the summary
table and the notes printed under it (trust, peers that fell behind)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

from sensornet.peers.core_summary import budget_lines
from sensornet.peers.telemetry import percentile


def summary_files(out: Path, name: str) -> list[Path]:
    """Peer ``name``'s summaries in ``out``, first run first (a restarted peer writes
    ``peer-<name>.restart<n>.json`` beside the earlier ones, never over them)."""
    def restart(p: Path) -> int:
        tail = p.name.removeprefix(f"peer-{name}").removesuffix(".json")
        return int(tail.removeprefix(".restart")) if tail else 0

    paths = [p for p in out.glob(f"peer-{name}*.json")
             if p.name == f"peer-{name}.json"
             or p.name.removeprefix(f"peer-{name}.restart").removesuffix(".json").isdigit()]
    return sorted(paths, key=restart)


def read_summaries(out: Path, names: list[str]) -> dict[str, dict]:
    """The newest summary of each peer (after restarts: the last run's); each carries the
    names of all its summary files under ``"summary_files"``."""
    found = {}
    for n in names:
        paths = summary_files(out, n)
        if paths:
            found[n] = json.loads(paths[-1].read_text())
            found[n]["summary_files"] = [p.name for p in paths]
    return found


def merge_recordings(out: Path) -> Path | None:
    """Merge the per-process ``.rrd`` files into ``<out>/recording.rrd`` with the Rerun CLI."""
    parts = sorted((out / "rerun").glob("*.rrd"))
    if not parts:
        return None
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    target = out / "recording.rrd"
    try:
        with target.open("wb") as fh:
            subprocess.run([exe, "rrd", "merge", *map(str, parts)], stdout=fh,
                           stderr=subprocess.DEVNULL, timeout=120, check=True,
                           env={**__import__("os").environ, "RERUN_ANALYTICS": "0"})
    except (OSError, subprocess.SubprocessError):
        target.unlink(missing_ok=True)
        return None
    return target


def format_summary(summaries: dict[str, dict]) -> str:
    """The end-of-run table: per peer OSPA local vs fused, communication cost per scan (the
    seed-004 tuples and the estimate bytes, both counted once per neighbour), traffic,
    rejections, age, latency."""
    def f(v, fmt="{:.1f}"):
        return "-" if v is None else fmt.format(v)

    head = ("| peer | scans | OSPA local | OSPA fused | tuples / scan | B / scan | msgs sent | "
            "msgs recv | kB sent | kB recv | rejected | mean age (scans) | "
            "latency median / p99 (ms) |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = [head]
    for n, s in summaries.items():
        cost = s.get("cost") or {}
        rows.append(
            f"| {n} | {s['scans']} | {f(s['mean_ospa_local'])} | {f(s['mean_ospa_fused'])} | "
            f"{f(cost.get('tuples_per_scan'), '{:.0f}')} | "
            f"{f(cost.get('estimate_bytes_to_neighbours_per_scan'), '{:.0f}')} | "
            f"{s['messages_sent']} | {s['messages_received']} | {s['bytes_sent'] / 1e3:.1f} | "
            f"{s['bytes_received'] / 1e3:.1f} | {s['rejected_total']} | "
            f"{f(s['mean_estimate_age'], '{:.2f}')} | {f(s['latency_ms_median'], '{:.2f}')} / "
            f"{f(s['latency_ms_p99'], '{:.2f}')} |")
    refused = {n: s.get("refused_by_transport") or {} for n, s in summaries.items()}
    if any(refused.values()):  # secure mode: what the access control refused on arrival
        rows += ["", "Refused by access control (secure mode; sender, message, key: count):", ""]
        for n, r in refused.items():
            if r:
                top = sorted(r.items(), key=lambda kv: -kv[1])
                rows.append(f"- {n}: {sum(r.values())} refused: "
                            + ", ".join(f"{label} x{c}" for label, c in top[:6])
                            + (f", ... ({len(top) - 6} more)" if len(top) > 6 else ""))
    stages = [("transit", "world -> peer"), ("local", "local filter"),
              ("neighbours", "waiting for neighbours"), ("fusing", "fusing")]
    parts = {n: s.get("latency_breakdown_ms_median") or {} for n, s in summaries.items()}
    if any(p.get(k) is not None for p in parts.values() for k, _ in stages):
        rows += ["", "Where the latency goes (median ms per scan):", "",
                 "| peer | " + " | ".join(label for _, label in stages) + " |",
                 "|---|" + "---:|" * len(stages)]
        for n, p in parts.items():
            rows.append(f"| {n} | " + " | ".join(f(p.get(k), "{:.2f}") for k, _ in stages)
                        + " |")
    return "\n".join(rows)


REALTIME_DEADLINE_SHARE = 0.05
"""Above this share of fusion rounds run at their deadline a run did not keep real time (the
network benchmark's criterion, with a p99 scan -> tracks latency under one scan interval)."""


def trust_note(summaries: dict[str, dict]) -> str | None:
    """Who was quarantined by whom and when (peers with ``fusion.trust``), one line per
    neighbour, then who was fused repaired or registered by whom, from when and how often
    (``fusion.trust_repair``, ``fusion.trust_register``), then whose weight the
    withheld-target test held at 0 by whom and how often, then whose estimates were refused
    for their size or reduced by whom (:func:`peers.core_summary.budget_lines`); None if
    nobody was any."""
    by: dict[str, list[str]] = {}
    for peer, s in sorted(summaries.items()):
        for ch in ((s.get("trust") or {}).get("changes") or []):
            if ch["to"] == "quarantined":
                by.setdefault(ch["neighbour"], []).append(f"{peer} at scan {ch['k']}")
            elif ch["from"] == "quarantined":
                by.setdefault(ch["neighbour"], []).append(f"readmitted by {peer} at scan "
                                                          f"{ch['k']}")
    fixed: dict[str, list[str]] = {}
    held: dict[str, list[str]] = {}
    for peer, s in sorted(summaries.items()):
        for n, rec in ((s.get("trust") or {}).get("neighbours") or {}).items():
            if rec.get("repairs"):
                fixed.setdefault(n, []).append(
                    f"{peer} from scan {rec['repaired_scan']} ({rec['repairs']} of "
                    f"{rec['rounds']} rounds)")
            if rec.get("holds"):
                held.setdefault(n, []).append(f"{peer} ({rec['holds']} of {rec['rounds']} "
                                              "rounds)")
    lines = [f"quarantined: {n} by " + ", ".join(v) for n, v in sorted(by.items())]
    lines += [f"repaired: {n} by " + ", ".join(v) for n, v in sorted(fixed.items())]
    lines += [f"held (withholding targets): {n} by " + ", ".join(v)
              for n, v in sorted(held.items())]
    lines += budget_lines(summaries)
    return "\n".join(lines) if lines else None


def realtime_note(summaries: dict[str, dict], interval_s: float, speed: float,
                  cores: int | None) -> str | None:
    """One paragraph when the peers did not keep real time (deadline fusions above
    :data:`REALTIME_DEADLINE_SHARE`, or the pooled p99 scan -> tracks latency over one scan
    interval), saying by how much and what to try; None when they did."""
    fusions = sum(s.get("stats", {}).get("fusions", 0) for s in summaries.values())
    late = sum(s.get("stats", {}).get("deadline_fusions", 0) for s in summaries.values())
    lat = sorted(x for s in summaries.values() for x in s.get("latency_ms_samples") or [])
    share = late / fusions if fusions else 0.0
    p99 = percentile(lat, 0.99)  # the sample at floor(0.99 n), as the benchmarks
    interval_ms = 1e3 * interval_s
    if share <= REALTIME_DEADLINE_SHARE and (p99 is None or p99 <= interval_ms):
        return None
    what = []
    if share > REALTIME_DEADLINE_SHARE:
        what.append(f"{100 * share:.1f} % of fusion rounds ran at their deadline")
    if p99 is not None and p99 > interval_ms:
        what.append(f"p99 scan -> tracks {p99:.0f} ms against a {interval_ms:.0f} ms scan "
                    f"interval")
    slower = speed / 2.0
    return (f"note: these {len(summaries)} peers did not keep real time at {speed:g}x "
            f"({'; '.join(what)}) on {cores or '?'} cores: the scores above include what "
            f"arrived too late. Run slower (--speed {slower:g}) or with fewer peers; "
            f"benchmarks/README.md has what such a machine sustains.")

