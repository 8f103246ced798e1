"""Several peers' trust tests at once (a peer host's co-hosted peers; :mod:`peers.batching`).

A peer's round of :meth:`peers.trust.Trust.weigh` is a handful of small array computations
(the divergences of five mixtures of a few components, a few offsets and charts), so its cost
is NumPy's per-call overhead, paid per peer. Written as generators of requests
(:meth:`Trust.weigh_steps`: each yields ``(op, *args)`` and is sent its result;
:func:`peers.trust_checks.run_alone` computes each request on its own),
:func:`run_together` runs many peers' rounds in lockstep and computes the requests of one
kind pending at once in one stacked computation (:data:`TOGETHER`), each the same numbers
to the bit as on its own (tests/test_trust_batch.py), so every peer's weights, records and
trust states are those of its own :meth:`Trust.weigh`.
"""

from __future__ import annotations

from collections.abc import Callable, Generator

import numpy as np
from sensornet.peers.trust_checks import ALONE, offset_chi2_many, offset_cusums
from sensornet.tracking.divergence import log_overlaps_many


def weigh_together(calls: list[tuple]) -> list[list[float] | BaseException]:
    """:meth:`peers.trust.Trust.weigh` of several peers' rounds: ``calls`` of
    ``(trust, k, rnd, own, inputs, weights, drop_suspects, late)`` (distinct Trust objects),
    each one's weights, or the exception its own call raised."""
    return run_together([trust.weigh_steps(*args) for trust, *args in calls])


def run_together(steps: list[Generator]) -> list:
    """The values of several trust generators (:func:`peers.trust_checks.run_alone`'s), run
    in lockstep: at each step the requests pending of one op are computed together
    (:data:`TOGETHER`; ops without a stacked form, and a stacked computation that raises,
    one by one). A generator that raises has its exception as its value."""
    out: list = [None] * len(steps)
    pending: dict[int, tuple] = {}

    def advance(i: int, value, first: bool = False) -> None:
        try:
            pending[i] = next(steps[i]) if first else steps[i].send(value)
        except StopIteration as stop:
            out[i] = stop.value
        except Exception as exc:  # noqa: BLE001 - that peer's alone, as its own call would
            out[i] = exc

    for i in range(len(steps)):
        advance(i, None, first=True)
    while pending:
        ops: dict[str, list[int]] = {}
        for i, request in pending.items():
            ops.setdefault(request[0], []).append(i)
        requests = pending
        pending = {}
        for op, ids in ops.items():
            together = TOGETHER.get(op)
            results = None
            if together is not None and len(ids) > 1:
                try:
                    results = together([requests[i][1:] for i in ids])
                except Exception:  # noqa: BLE001 - each on its own below, with its own error
                    results = None
            for n, i in enumerate(ids):
                if results is not None:
                    advance(i, results[n])
                    continue
                try:
                    value = ALONE[op](*requests[i][1:])
                except Exception as exc:  # noqa: BLE001 - raised into its generator
                    try:
                        pending[i] = steps[i].throw(exc)
                    except StopIteration as stop:
                        out[i] = stop.value
                    except Exception as err:  # noqa: BLE001
                        out[i] = err
                    continue
                advance(i, value)
    return out


def _overlaps(args: list[tuple]) -> list[np.ndarray]:
    """``"overlaps"``: :func:`tracking.divergence.log_overlaps_many`."""
    return log_overlaps_many([a[0] for a in args])


def _by_key(args: list[tuple], key: Callable, many: Callable) -> list:
    """``many`` of the requests with equal ``key(args)`` together, in the requests' order."""
    groups: dict = {}
    for n, a in enumerate(args):
        groups.setdefault(key(a), []).append(n)
    out: list = [None] * len(args)
    for ids in groups.values():
        for n, value in zip(ids, many([args[n] for n in ids]), strict=True):
            out[n] = value
    return out


def _chi2(args: list[tuple]) -> list:
    """``"chi2"``: :func:`peers.trust_checks.offset_chi2_many` of every peer's windows (the
    same ``windows``) in one batch, split back per peer."""
    def many(group: list[tuple]) -> list:
        flat = [w for offsets, _ in group for w in offsets]
        values = offset_chi2_many(flat, group[0][1])
        out, lo = [], 0
        for offsets, _ in group:
            out.append(values[lo:lo + len(offsets)])
            lo += len(offsets)
        return out
    return _by_key(args, lambda a: a[1], many)


def _cusums(args: list[tuple]) -> list:
    """``"cusums"``: :func:`peers.trust_checks.offset_cusums` of every peer's charts (the same
    offset and directions) in one batch, split back per peer."""
    def many(group: list[tuple]) -> list:
        G = np.concatenate([g for g, _, _, _ in group])
        values = offset_cusums(G, [i for _, infos, _, _ in group for i in infos],
                               group[0][2], group[0][3])
        out, lo = [], 0
        for g, _, _, _ in group:
            out.append(values[lo:lo + len(g)])
            lo += len(g)
        return out
    return _by_key(args, lambda a: (a[2], a[3].tobytes(), a[0].shape[1:]), many)


TOGETHER: dict[str, Callable[[list[tuple]], list]] = {
    "overlaps": _overlaps,
    "chi2": _chi2,
    "cusums": _cusums,
}
"""The requests computed together (each a list of the requests' arguments to a list of
results); the others (:data:`peers.trust_checks.ALONE`) one by one."""
