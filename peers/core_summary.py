"""What a peer reports for the run summary: its counts, scores and communication cost.

:meth:`peers.core.PeerCore.snapshot` and :meth:`~peers.core.PeerCore.cost` are these functions
of the core's counters (plain data out, nothing changed).
"""

from __future__ import annotations

from dataclasses import asdict


def core_cost(core) -> dict:
    """Tuples and bytes a peer sent per scan (estimates and forwards; docs/seed004.md:
    a 4-D Gaussian component 15 tuples, a 2-D measurement 2; no fusion mode here sends
    particles or a separate cardinality). ``tuples_per_scan`` counts a publication once
    per live neighbour (the seed's count), ``tuples_published_per_scan`` once; bytes are
    the encoded payloads, ``..._to_neighbours`` times the neighbours."""
    c = core.consensus
    return cost_per_scan(asdict(c.stats) | {"scans": c.stats.scans},
                         core.sent_bytes["estimate"], len(c.o.neighbours))


def core_snapshot(core) -> dict:
    """A :class:`~peers.core.PeerCore`'s counts, scores and state for the summary (plain data)."""
    c, s = core.consensus, core.scorer
    s.flush()  # a host's batched scores: all in before anything is read
    rejected = core.rejected + core.admission.rejected
    return {
        "peer": core.name,
        "scans": c.stats.scans,
        "last_k": c.last_k,
        "mean_ospa_local": s.mean("local"),
        "mean_ospa_fused": s.mean("fused"),
        "mean_gospa_local": s.results.mean("local"),
        "mean_gospa_fused": s.results.mean("fused"),
        "results_rows_dropped": s.results.dropped,
        "ospa_misses": dict(s.misses),
        "ospa_scored": dict(s.counts),
        "ospa_unscored": s.unscored,
        "rejected": dict(rejected),
        "rejected_total": sum(rejected.values()),
        "rejected_before_decoding": sum(core.admission.rejected.values()),
        "admitted_by_sender": dict(core.admission.admitted),
        "inbox_peak": core.admission.inbox_peak,
        "received_by_kind": dict(core.received),
        "bytes_received": sum(core.received_bytes.values()),
        "messages_received": sum(core.received.values()),
        "stale_scans": core.stale_scans,
        "reanchored": core.reanchored,
        "world_outages": list(core.world_outages),
        "ctl_end_while_world_alive": core.ctl_end_early,
        "peer_events": list(core.departures),
        "stats": asdict(c.stats),
        "cost": core.cost(),
        "nale": asdict(c.nale.counts),
        "fuser": dict(getattr(c.fuser, "counts", {})),
        "internal_errors": dict(c.errors),
        "prepared_steps": getattr(c.estimator, "prepared_hits", 0),
        "trust": c.trust.summary() if c.trust is not None else None,
        "budget": core_budget(core),
    }


def core_budget(core) -> dict:
    """Per member, what its size cost it (issue 36, :mod:`peers.budget`): estimates refused
    before decoding for their bytes (``refused``, ``refused_bytes``, by ``estimate/<name>``)
    and estimates reduced after (``reduced``, ``components_dropped``, ``largest``: by
    sender)."""
    a, b = core.admission, core.budget
    return {"refused": dict(a.over_budget), "refused_bytes": dict(a.over_budget_bytes),
            **(b.counts() if b is not None else
               {"reduced": {}, "components_dropped": {}, "largest": {}})}


def budget_lines(summaries: dict[str, dict]) -> list[str]:
    """One line per member that something was refused or reduced of, for the note under
    ``sensornet run``'s table: ``budget: s2 refused 40 estimates (9.6 MB) by s1, ...``."""
    by: dict[str, list[str]] = {}
    for peer, s in sorted(summaries.items()):
        b = s.get("budget") or {}
        names = {k.removeprefix("estimate/") for k in b.get("refused") or {}}
        names |= set(b.get("reduced") or {})
        for n in sorted(names):
            refused = (b.get("refused") or {}).get(f"estimate/{n}", 0)
            nbytes = (b.get("refused_bytes") or {}).get(f"estimate/{n}", 0)
            reduced = (b.get("reduced") or {}).get(n, 0)
            dropped = (b.get("components_dropped") or {}).get(n, 0)
            what = []
            if refused:
                what.append(f"{refused} refused for size ({nbytes / 1e6:.1f} MB)")
            if reduced:
                what.append(f"{reduced} reduced ({dropped} components cut)")
            by.setdefault(n, []).append(f"{peer}: " + ", ".join(what))
    return [f"over budget: {n}'s estimates, by " + "; ".join(v) for n, v in sorted(by.items())]


def cost_per_scan(stats: dict, sent_bytes: int, neighbours: int) -> dict:
    """Communication cost per scan from a peer's counters (plain data, for summaries)."""
    n = max(stats.get("scans", 0), 1)
    return {"tuples_per_scan": stats.get("tuples_to_neighbours", 0) / n,
            "tuples_published_per_scan": stats.get("tuples_out", 0) / n,
            "estimate_bytes_per_scan": sent_bytes / n,
            "estimate_bytes_to_neighbours_per_scan": sent_bytes * neighbours / n}
