"""What a peer process leaves behind: its summary, per-scan results, saved tracks and fault log.

Every file is named by the peer's stem (:func:`output_stem`), so a restarted peer never
overwrites its earlier files; a summary is written to a temporary name and renamed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from sensornet.peers.scan_results import write_part


def output_stem(out_dir: Path, name: str) -> str:
    """``peer-<name>``, or ``peer-<name>.restart<n>`` when an earlier run of this peer left
    files in ``out_dir`` (a restarted peer never overwrites its earlier summary or recording)."""
    def taken(stem: str) -> bool:
        return ((out_dir / f"{stem}.json").exists()
                or (out_dir / "rerun" / f"{stem}.rrd").exists())

    stem, n = f"peer-{name}", 0
    while taken(stem if n == 0 else f"{stem}.restart{n}"):
        n += 1
    return stem if n == 0 else f"{stem}.restart{n}"


class RunOutputs:
    """The output half of :class:`peers.runtime.PeerRuntime` (a mixin: it reads the runtime's
    ``core``, ``o``, ``stem``, ``telemetry``, ``transport`` and bookkeeping)."""

    def _write_results(self) -> None:
        """This peer's per-scan results (``<stem>.scans.msgpack``; the launcher merges every
        peer's into the run's ``results.parquet``, docs/results.md)."""
        try:
            write_part(self.core.scorer.results, self.name,
                       self.o.out_dir / f"{self.stem}.scans.msgpack",
                       self.telemetry.latency_by_scan)
        except Exception as exc:  # a failed write costs the table, never the summary
            print(f"{self.name}: per-scan results not written: {exc}", file=sys.stderr)

    def _save_tracks(self) -> None:
        if self.saved_tracks is not None:
            suffix = self.stem.removeprefix(f"peer-{self.name}")
            np.savez(self.o.out_dir / f"tracks-{self.name}{suffix}.npz",
                     **{f"k{k}": v for k, v in self.saved_tracks.items()})

    def _flush_fault_log(self) -> None:
        """Move the injected-fault records to ``faults-into-<peer>.csv``."""
        if self.o.faults is not None and self.o.out_dir is not None:
            suffix = self.stem.removeprefix(f"peer-{self.name}")
            self.o.faults.write_log(self.o.out_dir / f"faults-into-{self.name}{suffix}.csv",
                                    append=True)

    def summary(self) -> dict:
        s = self.core.snapshot()
        s.update(self.telemetry.summary(self.core.consensus.last_k))
        s["stop_reason"] = self.stop_reason
        s["peer_events"] = self.live_events[-1000:]
        s["injected_faults"] = self.o.faults.counts() if self.o.faults is not None else {}
        s["files"] = self.stem
        if self.killed_at is not None:
            s["killed_at_scan"] = self.killed_at
        if self.host is not None:
            s["host"] = self.host
        refusals = self.transport.refusals
        if refusals is not None:  # secure mode: what the access control refused on arrival
            s["refused_by_transport"] = refusals.counts()
            s["refused_by_transport_total"] = refusals.total()
            s["signatures_checked"] = self.transport.check_signatures
        if self.transport.recover:  # delivered late from a publisher's cache, or lost
            s["recovery"] = self.transport.recovery()
        errors = dict(s["internal_errors"])
        for name, n in s.pop("driver_errors").items():
            errors[name] = errors.get(name, 0) + n
        s["internal_errors"] = errors
        return s

    def write_summary(self) -> None:
        path = self.o.out_dir / f"{self.stem}.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.summary(), indent=2, default=float))
        tmp.replace(path)
