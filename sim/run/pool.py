"""The one process-pool loop: every study, sweep and campaign runs its runs through it.

Runs are pure and seeded (every draw comes from the scenario's seed and the run index), so a
result does not depend on where or in which order it was computed; :func:`map_runs` hands
the results back in the order of the inputs whatever the number of workers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, TextIO

from sensornet.sim.run.progress import Progress


def iter_pool(fn: Callable[..., Any], calls: Sequence[tuple], jobs: int = 1,
              initializer: Callable[..., None] | None = None,
              initargs: tuple = ()) -> Iterator[tuple[int, Any]]:
    """``(i, fn(*calls[i]))`` as each call finishes: in this process when ``jobs`` is 1 or
    there is one call, else over ``min(jobs, len(calls))`` worker processes. Closing the
    iterator early cancels the calls not yet started."""
    if jobs <= 1 or len(calls) <= 1:
        for i, args in enumerate(calls):
            yield i, fn(*args)
        return
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(calls)), initializer=initializer,
                               initargs=initargs)
    try:
        futures = {pool.submit(fn, *args): i for i, args in enumerate(calls)}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def map_runs(fn: Callable[..., Any], calls: Sequence[tuple], jobs: int = 1,
             label: str = "runs", progress: bool = True,
             stream: TextIO | None = None) -> list[Any]:
    """``[fn(*c) for c in calls]`` over ``jobs`` workers with one progress line on stderr;
    the results in the order of ``calls``."""
    out: list[Any] = [None] * len(calls)
    with Progress(len(calls), label, stream=stream, enabled=progress) as bar:
        for i, result in iter_pool(fn, calls, jobs):
            out[i] = result
            bar.advance()
    return out
