"""What a finished run left: the peers' summary files, the merged Rerun recording, the summary
table and the notes printed under it (trust, peers that fell behind)."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import msgpack
import numpy as np
from sensornet.peers.core_summary import budget_lines
from sensornet.peers.scan_results import read_part
from sensornet.peers.telemetry import percentile
from sensornet.sim.run.track_summary import track_summary


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
                           env={**os.environ, "RERUN_ANALYTICS": "0"})
    except (OSError, subprocess.SubprocessError):
        target.unlink(missing_ok=True)
        return None
    return target


def read_tables(out: Path) -> tuple[dict[str, dict[str, list]], dict]:
    """Every peer's per-scan rows from its parts in ``out`` (a restarted peer's parts
    concatenated, first run first) and the parts' meta: ``({peer: columns}, meta)``; parts that
    cannot be read are skipped (:func:`peers.scan_results.merge_parts` names them)."""
    tables: dict[str, dict[str, list]] = {}
    meta: dict = {}
    for path in sorted(out.glob("*.scans.msgpack"),
                       key=lambda q: (q.name.split(".")[0], len(q.name), q.name)):
        try:
            cols, m = read_part(path)
        except (ValueError, OSError, msgpack.UnpackException):
            continue
        if not cols["peer"]:
            continue
        meta = meta or m
        got = tables.setdefault(cols["peer"][0], {k: [] for k in cols})
        for k, v in cols.items():
            got[k].extend(v)
    return tables, meta


def add_track_summary(summaries: dict[str, dict], tables: dict[str, dict[str, list]],
                      meta: dict, out: Path | None = None) -> dict:
    """Put the run's track-level numbers (:func:`sim.run.track_summary.track_summary`) into
    each peer's summary under ``"tracks"`` (``local``, ``fused``, ``agreement`` and the run's
    ``label_agreement``) and, with ``out``, into its newest summary file; returns them."""
    if not tables or not meta:
        return {}
    ts = track_summary(tables, meta["position_index"], meta["cutoff"], meta.get("order", 2.0))
    for n, s in summaries.items():
        got = (ts.get("peers") or {}).get(n)
        if got is None:
            continue
        s["tracks"] = {**got, "label_agreement": ts.get("label_agreement"),
                       "label_agreement_target_scans": ts.get("confirmed")}
        files = s.get("summary_files")
        if out is not None and files:
            body = {k: v for k, v in s.items() if k != "summary_files"}
            path = out / files[-1]
            tmp = path.with_suffix(".tmp")
            tmp.write_text(json.dumps(body, indent=1, default=_plain))
            tmp.replace(path)
    return ts


def _plain(v):
    """JSON for NumPy scalars (the track numbers are floats and ints already)."""
    return v.item() if hasattr(v, "item") else str(v)


LEGEND = ("columns: OSPA and OSPA(2) in m, cut-off {c} (lower is better; OSPA per scan, "
          "OSPA(2) between tracks on 10-scan windows so ids count, both averaged over the "
          "run); local: each peer's own filter, "
          "fused: after fusing its neighbours'; ID sw / 1k: identity switches of the fused "
          "tracks per 1,000 true target-scans (lower is better); label agr.: share of the "
          "peer's fused target-scans where every other peer that tracks the target gives it the "
          "same id (higher is better); tuples and B: sent per scan to each neighbour; age: "
          "scans an estimate waited before fusion; latency: scan -> fused tracks")
"""What the end-of-run table's columns mean, one line under it (``{c}``: the cut-off)."""


def _finite(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def verdict(summaries: dict[str, dict]) -> str | None:
    """One line: did fusion help (fused OSPA below local) at each peer, by how much; None
    when no peer has both numbers."""
    pairs = {n: (s.get("mean_ospa_local"), s.get("mean_ospa_fused"))
             for n, s in summaries.items()}
    pairs = {n: (lo, fu) for n, (lo, fu) in pairs.items() if _finite(lo) and _finite(fu)}
    if not pairs:
        return None
    helped = [n for n, (lo, fu) in pairs.items() if fu < lo]
    change = [100.0 * (fu - lo) / lo for lo, fu in pairs.values() if lo > 0]
    lows = [lo for lo, _ in pairs.values()]
    fus = [fu for _, fu in pairs.values()]
    span = (f"fused OSPA {min(fus):.1f}-{max(fus):.1f} m against local "
            f"{min(lows):.1f}-{max(lows):.1f} m"
            + (f" (mean change {np.mean(change):+.0f} %)" if change else ""))
    if len(helped) == len(pairs):
        return f"verdict: fusion helped at every peer ({len(pairs)}): {span}"
    if not helped:
        return f"verdict: fusion did not help at any peer: {span}"
    worse = ", ".join(f"{n} {pairs[n][0]:.1f} -> {pairs[n][1]:.1f}" for n in pairs
                      if n not in helped)
    return (f"verdict: fusion helped at {len(helped)} of {len(pairs)} peers, not at {worse} "
            f"m: {span}")


def format_summary(summaries: dict[str, dict], missing: dict[str, str] | None = None,
                   cutoff: float | None = None) -> str:
    """The end-of-run table: per peer OSPA local vs fused, the track-level numbers (OSPA(2),
    identity switches, label agreement; ``"tracks"`` of a summary, see
    :func:`add_track_summary`), communication cost per scan (the seed-004 tuples and the
    estimate bytes, both counted once per neighbour), traffic, rejections, age, latency; then
    a legend line and the fusion verdict. ``missing``: ``{peer: why}`` of peers that left no
    summary (killed), each a row scored as misses (OSPA at ``cutoff``). A run that played no
    scan says so instead of a table of NaN."""
    def f(v, fmt="{:.1f}"):
        return fmt.format(v) if _finite(v) else "-"

    missing = missing or {}
    if summaries and not missing and not any(s.get("scans") for s in summaries.values()):
        return (f"no scan was played: the run stopped before its first scan, so nothing was "
                f"tracked or scored ({len(summaries)} peers, 0 scans)")
    head = ("| peer | scans | OSPA local | OSPA fused | OSPA(2) local | OSPA(2) fused | "
            "ID sw / 1k | label agr. | tuples / scan | B / scan | msgs sent | "
            "msgs recv | kB sent | kB recv | rejected | mean age (scans) | "
            "latency median / p99 (ms) |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
            "---:|")
    rows = [head]
    for n, s in summaries.items():
        cost = s.get("cost") or {}
        tr = s.get("tracks") or {}
        lo, fu = tr.get("local") or {}, tr.get("fused") or {}
        agr = tr.get("agreement")
        rows.append(
            f"| {n} | {s['scans']} | {f(s['mean_ospa_local'])} | {f(s['mean_ospa_fused'])} | "
            f"{f(lo.get('ospa2'))} | {f(fu.get('ospa2'))} | "
            f"{f(fu.get('switches_per_1000'))} | "
            f"{f(None if agr is None else 100 * agr, '{:.1f} %')} | "
            f"{f(cost.get('tuples_per_scan'), '{:.0f}')} | "
            f"{f(cost.get('estimate_bytes_to_neighbours_per_scan'), '{:.0f}')} | "
            f"{s['messages_sent']} | {s['messages_received']} | {s['bytes_sent'] / 1e3:.1f} | "
            f"{s['bytes_received'] / 1e3:.1f} | {s['rejected_total']} | "
            f"{f(s['mean_estimate_age'], '{:.2f}')} | {f(s['latency_ms_median'], '{:.2f}')} / "
            f"{f(s['latency_ms_p99'], '{:.2f}')} |")
    for n, why in missing.items():
        c = f(cutoff)
        rows.append(f"| {n} ({why}: no summary, every scan scored a miss) | - | {c} | {c} | "
                    f"{c} | {c} | - | - | - | - | - | - | - | - | - | - | - / - |")
    rows.append("")
    rows.append(LEGEND.format(c=f"{cutoff:g} m" if _finite(cutoff) else "c"))
    line = verdict(summaries)
    if line:
        rows.append(line + (f"; no verdict for {', '.join(missing)} (no summary)" if missing
                            else ""))
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

