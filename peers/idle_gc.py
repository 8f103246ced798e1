"""Full garbage collections between scans, not in the middle of one.

CPython collects its oldest generation when enough younger collections have passed, wherever
the program is: in a peer host of 50 peers a full collection took up to 30 ms (4 in a
100-scan run, measured with ``gc.callbacks``), and one falling inside a scan delays every
peer's tracks of that scan, which alone is 1 % of the run's samples: the p99 latency. The
young generations (in the same run: generation 0 at most 1.4 ms, generation 1 at most 6 ms)
stay automatic; the full one is taken when the loop is idle between scans (no consensus in
progress: a peer waiting for its neighbours' next round is not idle) and the next scan is far
enough away (:meth:`IdleCollector.idle`), or, if the loop is never idle long enough, once it
is :data:`OVERDUE` times later than CPython would have been (memory stays bounded).
"""

from __future__ import annotations

import gc
import time

OFF = 1 << 30
"""Generation-2 threshold while the collector is on: never reached by counting."""
OVERDUE = 10
"""A full collection waits at most this many times CPython's own generation-2 threshold."""


class IdleCollector:
    """Takes CPython's full collections at idle moments of a loop (see the module)."""

    def __init__(self, margin_ms: float = 5.0) -> None:
        self.margin_ms = margin_ms
        self.every = gc.get_threshold()[2]
        """Generation-1 collections between full ones, as CPython would count them."""
        self.last_ms = 20.0
        """The last full collection's duration (a first guess until one is measured)."""
        self.collections = 0
        self.overdue = 0
        self.worst_ms = 0.0
        self._saved: tuple[int, int, int] | None = None

    def start(self) -> None:
        """From now on, full collections only through :meth:`idle` (the young ones as before)."""
        t = gc.get_threshold()
        self._saved = t
        self.every = t[2]
        gc.set_threshold(t[0], t[1], OFF)

    def stop(self) -> None:
        if self._saved is not None:
            gc.set_threshold(*self._saved)
            self._saved = None

    def due(self) -> bool:
        return self._saved is not None and gc.get_count()[2] >= self.every

    def idle(self, gap_ms: float) -> bool:
        """The loop has nothing to do for about ``gap_ms``: collect if a full collection is
        due and fits (twice the last one's time plus the margin), or is overdue. True if it
        collected."""
        if not self.due():
            return False
        late = gc.get_count()[2] >= OVERDUE * self.every
        if not late and gap_ms < 2.0 * self.last_ms + self.margin_ms:
            return False
        t0 = time.perf_counter()
        gc.collect(2)
        self.last_ms = (time.perf_counter() - t0) * 1e3
        self.worst_ms = max(self.worst_ms, self.last_ms)
        self.collections += 1
        self.overdue += late
        return True

    def counts(self) -> dict:
        return {"full_collections": self.collections, "overdue": self.overdue,
                "worst_ms": round(self.worst_ms, 2)}
