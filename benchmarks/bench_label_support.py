"""The LMB peers' label holder masks (``peers.label_support.LabelSupport``) against a git
revision's, on the 50-peer twin (issue 33).

Runs the twin of ``bench_fifty.py --twin --kinds lmb`` (50 peers, degree 4, L = 2, the host's
shared decode and batched fusions) alternately with this tree's ``LabelSupport`` and with
``--against REV``'s methods and properties (and its ``decode``, as the consensus calls it)
swapped in (REV at or after 99526bc: masks as words), the world's run generated once outside
the timed part. Prints each pair's CPU ms per peer-scan, the medians and the pairs' ratios,
both sides' mean fused OSPA and whether every peer's results table (fused and local states,
track ids, OSPA per scan) is the same. One process, so both sides share the interpreter, the
imports and the machine's minutes.

    python benchmarks/bench_label_support.py --against 99526bc
    python benchmarks/bench_label_support.py --against 99526bc --pairs 4 --scans 100
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

if not __package__:  # `python benchmarks/bench_label_support.py`: the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import sensornet.peers.consensus as consensus
from sensornet.peers.label_support import LabelSupport

from benchmarks.bench_label_memory import module_at, run_against


def method_sets(rev: str) -> dict[str, dict[object, dict[str, object]]]:
    """``{"now": ..., "rev": ...}``: LabelSupport's functions and properties defined in its
    class body, and the ``decode`` the consensus calls on every labelled estimate."""
    def funcs(c: type) -> dict[str, object]:  # properties too (the stores' deferred reads)
        return {k: v for k, v in vars(c).items()
                if isinstance(v, types.FunctionType | property)}
    old = module_at(rev, "peers/label_support.py")
    return {"now": {LabelSupport: funcs(LabelSupport), consensus: {"decode": consensus.decode}},
            "rev": {LabelSupport: funcs(old.LabelSupport), consensus: {"decode": old.decode}}}


def main(argv: list[str] | None = None) -> int:
    _, line, tables = run_against(argv, __doc__, method_sets, "lmb", "label holder masks",
                                  pairs=2, tables=True)
    print(f"{line}; every peer's results table the same: {tables['rev'] == tables['now']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
