"""The twin over several cores: :func:`sim.run.twin.run_twin` with ``workers=N`` (issue 34).

The peers are split over N forked worker processes (:func:`split_peers`: balanced by count,
fewest links cut), each with its own event queue holding its peers' world events (in the
one-process order) and a clock over its peers only (:class:`sim.run.twin._WorkerClock`). The
parent plays the virtual instants (a conservative, lock-step discrete-event simulation): at
instant ``t`` (the earliest head of all queues and of the messages in flight) every worker with
work at ``t`` handles all of it (a *wave*); what a peer publishes to a peer of another worker
comes back to the parent and goes into that worker's queue at ``t + delay`` with its next
command. With zero-delay links an instant takes several waves until no worker has work at
``t``; then, with ``batch``, every worker fuses its ready rounds (its own
:class:`peers.batching.FusionBatch`, as one host per worker), which may start more waves at
``t``, as the one-process loop does once the instant's events are handled.

A peer sees the same events at the same virtual times as in one process; only the order of one
instant's events from peers of different workers can differ (a worker's own first, then the
other's, wave by wave). The consensus fuses a round once all inputs are in, senders sorted, so
the tracks and summaries do not depend on it: tests/test_twin_split.py checks them to the bit
against one process (with ``batch``, each worker stacks only its own peers' rounds, and a
stacked fusion's last bits move with the stack: equal to 1e-12, as batch against none). Link
faults are counter-based per message and link (:mod:`peers.faults`),
so each worker decides its senders' messages as one process would; the merged fault log holds
the same records, ordered by decision time. At the end each worker sends its peers' cores back
pickled (closures, e.g. the scorer's truth function, replaced by stubs that raise); a worker's
exception is a one-line error here, and the workers are always ended and reaped.
"""

from __future__ import annotations

import io
import itertools
import multiprocessing
import pickle
import threading
import time
import types

from sensornet.peers.batching import FusionBatch

try:  # optional (scikit-learn's dependency): without it a worker keeps BLAS's threads
    from threadpoolctl import threadpool_info, threadpool_limits
except ImportError:
    threadpool_info = threadpool_limits = None

EXHAUSTIVE = 16
"""Up to this many peers the two-way split is searched over every balanced partition."""


def split_peers(names: list[str], listeners: dict[str, list[str]],
                workers: int) -> list[list[str]]:
    """The peers' groups, one per worker: sizes differing by at most one; for two workers
    and up to :data:`EXHAUSTIVE` peers the partition that cuts the fewest subscriptions
    (sender -> listener pairs across groups; ties: the earliest in name order), else
    consecutive runs of ``names``."""
    n = len(names)
    workers = max(1, min(workers, n))
    if workers == 2 and n <= EXHAUSTIVE:
        def cut(group: set[str]) -> int:
            return sum((s in group) != (r in group) for s in names for r in listeners[s])
        best = min((set(c) for c in itertools.combinations(names, (n + 1) // 2)
                    if names[0] in c), key=cut)
        return [[m for m in names if m in best], [m for m in names if m not in best]]
    size, extra = divmod(n, workers)
    out, i = [], 0
    for w in range(workers):
        j = i + size + (w < extra)
        out.append(names[i:j])
        i = j
    return out


def _local_function(obj) -> bool:
    return isinstance(obj, types.FunctionType) and "<locals>" in obj.__qualname__


_LOCKS = (type(threading.Lock()), type(threading.RLock()))


class _Pickler(pickle.Pickler):
    """Pickles a worker's cores; closures (not picklable) become stubs by name, locks (the
    runtime's, unused on the twin) fresh locks."""

    def persistent_id(self, obj):
        if isinstance(obj, _LOCKS):
            return ("lock", isinstance(obj, _LOCKS[1]))
        return ("closure", obj.__qualname__) if _local_function(obj) else None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid):
        if pid[0] == "lock":
            return threading.RLock() if pid[1] else threading.Lock()
        name = pid[1]

        def stub(*args, **kwargs):
            raise RuntimeError(f"{name} stayed in a twin worker (run_twin workers > 1)")
        return stub


def _dumps(obj) -> bytes:
    buf = io.BytesIO()
    _Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buf.getvalue()


def _results(clock, blas: list[int] | None) -> bytes:
    r, f = clock.result, clock.faults
    return _dumps({"peers": clock.peers, "tracks": r.tracks, "stops": r.stops, "ages": r.ages,
                   "transport_drops": r.transport_drops, "ospa": r.ospa,
                   "faults": (f.log, f._counts) if f is not None else None,
                   "blas_threads": blas})


def one_blas_thread() -> list[int] | None:
    """Limit this process's BLAS libraries (NumPy's and SciPy's OpenBLAS) to one thread each;
    their thread counts after, or None without threadpoolctl. Why: N workers each with a
    thread per core oversubscribe the cores, and the twin's matrices are small (4x4 to 6x6):
    the spare threads only spin (paris-8 traffic twin, 5 min, two workers, 3 runs each way
    alternated: 0.89x the CPU with one thread (GM-PHD), 0.91x (LMB), the same tracks). A
    forked worker has NumPy loaded already, so ``OPENBLAS_NUM_THREADS`` would come too late:
    threadpoolctl sets it in the library."""
    if threadpool_limits is None:
        return None
    threadpool_limits(1, user_api="blas")
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def _worker(conn, others: list, clock, names: list[str], batch: bool) -> None:
    """A worker's loop over its ``clock`` (a :class:`sim.run.twin._WorkerClock`):
    ``("wave", t, incoming)``, ``("fuse", t, incoming)`` or ``("end",)`` from the parent;
    replies the clock's ``reply``, the results, or ``("error", line)``."""
    for c in others:
        c.close()
    try:
        blas = one_blas_thread()
        clock.start(names, FusionBatch() if batch else None)
        while True:
            cmd = conn.recv()
            c0 = time.process_time()
            if cmd[0] == "end":
                conn.send_bytes(b"R" + _results(clock, blas))
                return
            if cmd[0] == "wave":
                clock.wave(cmd[1], cmd[2])
            else:
                clock.wave(cmd[1], cmd[2])  # nothing at t is queued: only the deliveries
                clock.fuse(cmd[1])
            conn.send(clock.reply(time.process_time() - c0))
    except (EOFError, BrokenPipeError):
        return  # the parent is gone
    except BaseException as e:  # noqa: BLE001 - any failure becomes the parent's error line
        line = (str(e).splitlines() or [""])[0][:300]
        try:
            conn.send(("error", f"{type(e).__name__}: {line}" if line else type(e).__name__))
        except (OSError, ValueError):
            pass


def play(clocks: list, groups: list[list[str]], names: list[str],
         batch: bool) -> tuple[list[dict], dict]:
    """Run each of ``clocks`` (a :class:`sim.run.twin._WorkerClock` per group of peers, its
    queue filled) in a forked worker, instant by instant (module docstring); returns each
    worker's results (:func:`_results`, unpickled) and the counts of :func:`_play` with each
    worker's BLAS threads (:func:`one_blas_thread`, each library's; None: not limited). Raises
    RuntimeError (one line) if a worker fails or dies; the workers are always reaped."""
    owner = {n: w for w, g in enumerate(groups) for n in g}
    ctx = multiprocessing.get_context("fork")
    conns, procs = [], []
    try:
        for w, c in enumerate(clocks):
            parent, child = ctx.Pipe()
            conns.append(parent)
            p = ctx.Process(target=_worker, args=(child, list(conns), c, names, batch),
                            name=f"twin-worker-{w}", daemon=True)
            p.start()
            child.close()
            procs.append(p)
        heads = [c.queue[0][0] if c.queue else None for c in clocks]
        stats = _play(conns, procs, groups, owner, heads)
        for c in conns:
            c.send(("end",))
        parts = [_receive(c, p, g, raw=True) for c, p, g in zip(conns, procs, groups,
                                                                    strict=True)]
    finally:
        for c in conns:
            c.close()
        for p in procs:
            p.join(timeout=5.0)
            if p.is_alive():
                p.kill()
                p.join()
    results = [_Unpickler(io.BytesIO(b)).load() for b in parts]
    return results, {"groups": groups, **stats,
                     "blas_threads": [r["blas_threads"] for r in results]}


def _receive(conn, proc, group: list[str], raw: bool = False):
    """A worker's reply, or RuntimeError (one line) if it failed or died."""
    try:
        msg = conn.recv_bytes() if raw else conn.recv()
    except (EOFError, OSError):
        proc.join(timeout=5.0)
        raise RuntimeError(f"twin worker {proc.name} (peers {', '.join(group)}) died "
                           f"(exit code {proc.exitcode})") from None
    if raw and msg[:1] == b"R":  # the results (an error tuple comes pickled by send())
        return msg[1:]
    if raw:
        msg = pickle.loads(msg)
    if isinstance(msg, tuple) and msg[0] == "error":
        raise RuntimeError(f"twin worker {proc.name} (peers {', '.join(group)}) failed: "
                           f"{msg[1]}")
    return msg


def _play(conns: list, procs: list, groups: list[list[str]], owner: dict[str, int],
          heads: list) -> dict:
    """The instants, in order, until every queue is empty and nothing is in flight; returns
    counts: instants, waves, messages between workers, the workers' CPU seconds in commands
    (``cpu``) and the sum over waves of the slowest worker's (``critical_cpu``: the wall time
    of a machine with a free core per worker, less the pipes)."""
    n = len(conns)
    pending: list[list] = [[] for _ in range(n)]
    jobs = [False] * n
    stats = {"instants": 0, "waves": 0, "messages": 0, "cpu": 0.0, "critical_cpu": 0.0}

    def due(w: int) -> float | None:
        ts = [m[0] for m in pending[w]] + ([heads[w]] if heads[w] is not None else [])
        return min(ts) if ts else None

    def command(ws: list[int], cmd: str, t: float) -> None:
        for w in ws:
            conns[w].send((cmd, t, pending[w]))
            pending[w] = []
        slowest = 0.0
        for w in ws:
            _, out, heads[w], jobs[w], cpu = _receive(conns[w], procs[w], groups[w])
            for m in out:
                pending[owner[m[2]]].append(m)
            slowest = max(slowest, cpu)
            stats["cpu"] += cpu
            stats["messages"] += len(out)
        stats["critical_cpu"] += slowest
        stats["waves"] += 1

    while True:
        dues = [due(w) for w in range(n)]
        if all(d is None for d in dues):
            return stats
        t = min(d for d in dues if d is not None)
        stats["instants"] += 1
        while True:
            active = [w for w in range(n) if due(w) == t]
            if active:
                command(active, "wave", t)
            elif any(jobs):
                command([w for w in range(n) if jobs[w]], "fuse", t)
            else:
                break
