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

import functools
from collections.abc import Callable, Generator

import numpy as np
from sensornet.peers.trust_checks import (
    ALONE,
    _others,
    _ranks,
    gated,
    information_sums,
    neighbour_tests_many,
    offset_chi2_stacked,
    offset_cusums,
    own_tests_many,
    position_block,
    target_mass,
    unmatched_sums,
    withheld_increments,
)
from sensornet.tracking.divergence import log_overlaps_many
from sensornet.tracking.mixture import GaussianMixture


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
    """``"chi2"``: :func:`peers.trust_checks.offset_chi2_stacked` of every peer's windows
    (the same ``windows``) in one batch, split back per peer."""
    def many(group: list[tuple]) -> list:
        flat = [w for stacks, _ in group for w in stacks]
        values = offset_chi2_stacked(flat, group[0][1])
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


def _unmatched(args: list[tuple]) -> list[np.ndarray]:
    """``"unmatched"``: :func:`peers.trust_checks.unmatched_weights`' ``U`` of every request
    (the same ``pos``, ``min_weight``, ``gate``, ``chi2``) at once: every group's pairs of
    target components gated in one computation (:func:`gated` is per pair), then each
    group's sums as there (its own products: the same numbers)."""
    return _by_key(args, lambda a: (tuple(a[1]), a[2], a[3], a[4]), _unmatched_group)


def _unmatched_group(group: list[tuple]) -> list[np.ndarray]:
    pos, min_weight, gate, chi2 = group[0][1:]
    lens = [[len(D) for D in mixes] for mixes, *_ in group]
    full = [D for (mixes, *_), z in zip(group, lens, strict=True)
            for D, c in zip(mixes, z, strict=True) if c]
    out = [np.zeros((len(z), len(z))) for z in lens]
    if not full:
        return out
    sizes = [c for z in lens for c in z if c]
    req = np.repeat([r for r, z in enumerate(lens) for c in z if c], sizes)  # per component
    inp = np.repeat([i for z in lens for i, c in enumerate(z) if c], sizes)
    keep = np.flatnonzero(np.concatenate([D.weights for D in full]) >= min_weight)
    if not len(keep):
        return out
    w = np.concatenate([D.weights for D in full])[keep]
    X = np.concatenate([D.means for D in full])[keep][:, pos]
    P = (position_block(np.concatenate([D.covs for D in full])[keep], pos)
         if chi2 is not None else np.zeros((len(keep), 2, 2)))
    counts = np.bincount(req[keep], minlength=len(group)).tolist()
    owner = inp[keep]
    ends = np.cumsum(counts).tolist()
    live = [(r, C, e) for r, (C, e) in enumerate(zip(counts, ends, strict=True)) if C]
    a = np.concatenate([_square(C)[0] + (e - C) for _, C, e in live])
    b = np.concatenate([_square(C)[1] + (e - C) for _, C, e in live])
    dP = np.linalg.det(P) if chi2 is not None else None  # per component, not per pair
    close = gated(X[a] - X[b], P[a], P[b], gate, chi2, *((dP[a], dP[b]) if chi2 is not None
                                                          else ()))  # near(), pair by pair
    n = max(len(z) for z in lens)
    hit = np.zeros((len(keep), n), bool)  # (C, n): an input's target within the gate
    hit[a[close], owner[b[close]]] = True
    rows = req[keep] * n + owner  # each component's (request, input), in order
    seg = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    U = np.zeros((len(group) * n, n))
    U[rows[seg]] = unmatched_sums(w, hit, np.diff(np.r_[seg, len(rows)]).tolist())
    U = U.reshape(len(group), n, n)
    return [U[r, :len(z), :len(z)] for r, z in enumerate(lens)]


@functools.lru_cache(maxsize=256)
def _square(C: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of every entry of a ``(C, C)`` matrix, row-major (made once per ``C``,
    read-only)."""
    out = np.repeat(np.arange(C), C), np.tile(np.arange(C), C)
    for x in out:
        x.flags.writeable = False
    return out


def _offsets(args: list[tuple]) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """``"offsets"``: :func:`peers.trust_checks.offset_information_many` of every request
    (each its own reference; the same ``pos``, ``min_weight``, ``gate``, ``chi2``) at once:
    every component's nearest reference component (the references padded at their end
    with components at infinity, never nearest), gate and inverse in one computation, the
    sums per mixture as there."""
    return _by_key(args, lambda a: (tuple(a[2]), a[3], a[4], a[5]), _offsets_group)


def _offsets_group(group: list[tuple]) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    pos, min_weight, gate, chi2 = group[0][2:]
    out = [[(np.zeros((2, 2)), np.zeros(2)) for _ in mixes] for _, mixes, *_ in group]
    # each mixture's components of at least min_weight, their positions and position
    # blocks, once per mixture object: a neighbour's estimate is one object at all its
    # co-hosted receivers (peers.host_parts.SharedDecode), so it is in several requests
    picked: dict[int, tuple] = {}

    def pick(M: GaussianMixture) -> tuple:
        v = picked.get(id(M))  # the objects are held by the requests meanwhile
        if v is None:
            a = M.weights >= min_weight
            c = int(np.count_nonzero(a))
            v = picked[id(M)] = (c, M.means[a][:, pos], position_block(M.covs[a], pos)
                                 if c else None)
        return v

    todo = []  # (request, its reference's target components, [(mixture, its pick)])
    for r, (ref, mixes, *_) in enumerate(group):
        if len(ref) == 0:
            continue
        b = pick(ref)  # its target components (own's: one object per request)
        if not b[0]:
            continue
        sel = [(i, pick(M)) for i, M in enumerate(mixes) if len(M)]
        sel = [(i, v) for i, v in sel if v[0]]
        if sel:
            todo.append((r, b, sel))
    if not todo:
        return out
    sizes = [b[0] for _, b, _ in todo]
    mb = np.full((len(todo), max(sizes), 2), np.inf)  # (g, m, 2): padded at infinity
    Pb = np.zeros((len(todo), max(sizes), 2, 2))
    at = np.repeat(np.arange(len(todo)), sizes), _ranks(tuple(sizes))
    mb[at] = np.concatenate([b[1] for _, b, _ in todo])
    Pb[at] = np.concatenate([b[2] for _, b, _ in todo])
    rows = np.repeat(np.arange(len(todo)), [sum(v[0] for _, v in sel) for _, _, sel in todo])
    ma = np.concatenate([v[1] for _, _, sel in todo for _, v in sel])  # (n, 2)
    Pa = np.concatenate([v[2] for _, _, sel in todo for _, v in sel])  # (n, 2, 2)
    diff = ma[:, None, :] - mb[rows]  # (n, top, 2)
    nearest = np.argmin(np.linalg.norm(diff, axis=2), axis=1)
    d = diff[np.arange(len(ma)), nearest]
    Pn = Pb[rows, nearest]
    ok = gated(d, Pa, Pn, gate, chi2)
    if not ok.any():
        return out
    counts = [v[0] for _, _, sel in todo for _, v in sel]
    hits = np.add.reduceat(ok, np.cumsum([0, *counts[:-1]])).tolist()  # gated per mixture
    infos = iter(information_sums(Pa[ok] + Pn[ok], d[ok], hits))  # every mixture's at once
    for r, _, sel in todo:
        for i, _ in sel:
            info = next(infos)
            if info is not None:
                out[r][i] = info
    return out


def _tests(args: list[tuple]) -> list[list[float]]:
    """``"tests"``: :func:`peers.trust_checks.neighbour_tests` of every request (the same
    config and number of inputs) at once: :func:`peers.trust_checks.neighbour_tests_many`
    of them stacked (every peer's neighbours in one computation, the one formula)."""
    def many(group: list[tuple]) -> list[list[float]]:
        def stack(i: int) -> np.ndarray | None:
            return None if group[0][i] is None else np.stack([a[i] for a in group])
        return neighbour_tests_many(group[0][0], *(stack(i) for i in range(1, 7))).tolist()
    return _by_key(args, lambda a: (a[0], len(a[6]), a[2] is None, a[5] is None), many)


def _own_tests(args: list[tuple]) -> list[list[float]]:
    """``"own_tests"``: :func:`peers.trust_checks.own_tests_many` of every request (the same
    config and number of inputs) stacked."""
    def many(group: list[tuple]) -> list[list[float]]:
        L0 = None if group[0][2] is None else np.stack([a[2] for a in group])
        return own_tests_many(group[0][0], np.stack([a[1] for a in group]), L0,
                              np.array([a[3] for a in group], float),
                              np.array([a[4] for a in group], float)).tolist()
    return _by_key(args, lambda a: (a[0], len(a[3]), a[2] is None), many)


def _masses(args: list[tuple]) -> list[tuple[list[float], list[float]]]:
    """``"masses"``: each mixture's mass and target mass, computed once per mixture object
    however many peers' requests hold it (a neighbour's estimate is one object at every
    co-hosted receiver: :class:`peers.host_parts.SharedDecode`), by the same functions."""
    seen: dict[tuple[int, float], tuple[float, float]] = {}
    out = []
    for mixes, min_weight in args:
        masses, targets = [], []
        for D in mixes:
            key = (id(D), min_weight)  # the objects are held by the requests meanwhile
            v = seen.get(key)
            if v is None:
                v = seen[key] = (D.mass, target_mass(D, min_weight))
            masses.append(v[0])
            targets.append(v[1])
        out.append((masses, targets))
    return out


def _withheld(args: list[tuple]) -> list[np.ndarray]:
    """``"withheld"``: :func:`peers.trust_checks.withheld_increments` of the requests with
    as many inputs (and the same rates) stacked: the same elementwise operations, sorts and
    medians per stack."""
    def many(group: list[tuple]) -> list[np.ndarray]:
        U, tm, refs = (np.stack([a[i] for a in group]) for i in range(3))
        return list(withheld_increments(U, tm, refs, *group[0][3:]))
    return _by_key(args, lambda a: (a[0].shape, a[3], a[4], a[5]), many)


def _relative(args: list[tuple]) -> list[dict]:
    """``"relative"``: :func:`peers.trust_checks.relative_offsets` of every request at once:
    the determinants of all, then the solves, leave-one-out medians (sorts) and products of
    the requests with as many offsets kept stacked (per matrix and per row, the same
    numbers)."""
    out: list = [None] * len(args)
    todo = []
    for r, (infos, among) in enumerate(args):
        if len(among) < 3:
            out[r] = infos
        else:
            todo.append(r)
    if not todo:
        return out
    I = np.array([args[r][0][s][0] for r in todo for s in args[r][1]])  # (m, 2, 2)
    ok = (np.linalg.det(I) > 1e-12).tolist()
    groups: dict[int, list[tuple[int, list[str]]]] = {}
    lo = 0
    for r in todo:
        infos, among = args[r]
        names = [s for s, good in zip(among, ok[lo:lo + len(among)], strict=True) if good]
        lo += len(among)
        if len(names) < 3:
            out[r] = infos
        else:
            groups.setdefault(len(names), []).append((r, names))
    for n, members in groups.items():
        info = np.array([[args[r][0][s][0] for s in names] for r, names in members])
        y0 = np.array([[args[r][0][s][1] for s in names] for r, names in members])
        g = len(members)
        b = np.linalg.solve(info.reshape(g * n, 2, 2), y0.reshape(g * n, 2, 1))[..., 0]
        b = b.reshape(g, n, 2)
        S = np.sort(b[:, _others(n)], axis=2)  # (g, n, n - 1, 2)
        h = (n - 1) // 2
        med = S[:, :, h] if (n - 1) % 2 else (S[:, :, h - 1] + S[:, :, h]) * 0.5
        med = np.where(np.isnan(S).any(axis=2), np.nan, med)  # np.median: NaN where any is
        y = np.einsum("nij,nj->ni", info.reshape(g * n, 2, 2),
                      (b - med).reshape(g * n, 2)).reshape(g, n, 2)
        for (r, names), yr in zip(members, y, strict=True):
            infos = args[r][0]
            res = dict(infos)
            res.update({s: (infos[s][0], yr[i]) for i, s in enumerate(names)})
            out[r] = res
    return out


TOGETHER: dict[str, Callable[[list[tuple]], list]] = {
    "relative": _relative,
    "withheld": _withheld,
    "masses": _masses,
    "tests": _tests,
    "own_tests": _own_tests,
    "overlaps": _overlaps,
    "unmatched": _unmatched,
    "offsets": _offsets,
    "chi2": _chi2,
    "cusums": _cusums,
}
"""The requests computed together (each a list of the requests' arguments to a list of
results); the others (:data:`peers.trust_checks.ALONE`) one by one."""
