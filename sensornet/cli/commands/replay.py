"""``replay``: feed a recorded run through the peers offline (bit for bit, or a what-if)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sensornet.cli.common import UserError
from sensornet.sim.run.replay import replay
from sensornet.sim.scenario import ScenarioError


def cmd_replay(args: argparse.Namespace) -> int:
    path = Path(args.path)
    files = sorted((path / "record").glob("*.mcap")) if path.is_dir() else [path]
    if not files or not all(f.is_file() for f in files):
        raise UserError(f"no recording at {path} (record with 'sensornet run --record')")
    if args.peer:
        files = [f for f in files if f.stem.split(".")[0] == f"peer-{args.peer}"]
        if not files:
            raise UserError(f"no recording of peer {args.peer!r} in {path}")
    ok = True
    changed = False
    for i, f in enumerate(files):
        try:
            r = replay(f, args.set or [])
        except (ValueError, ScenarioError, OSError) as exc:
            raise UserError(f"{f}: {exc}") from None
        if i == 0:  # after the first replay: a refused --set is one line, no table head
            print("| peer | file | scans | tracks recorded | replayed identical | "
                  "mean OSPA fused |")
            print("|---|---|---:|---:|---|---:|")
        same = r.identical
        ok = ok and (same or bool(args.set))
        changed = changed or not same
        print(f"| {r.peer} | {f.name} | {r.snapshot['scans']} | {len(r.recorded)} | "
              f"{'yes' if same else 'NO'} | {r.snapshot['mean_ospa_fused']:.2f} |", flush=True)
    if args.set and changed:
        print("(with --set the replay is a what-if run: its tracks are expected to differ)")
    elif args.set:
        print("(with --set the replay is a what-if run; these settings changed none of the "
              "tracks)")
    return 0 if ok else 1
