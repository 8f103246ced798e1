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
    segment_sums,
    target_mass,
    unmatched_sums,
    withheld_increments,
)
from sensornet.tracking.divergence import BLOCK_PAIRS, log_overlaps_many
from sensornet.tracking.gaussian import inv_det_spd, log_gaussian
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
    """``"overlaps"``: :func:`shared_log_overlaps`."""
    return shared_log_overlaps([a[0] for a in args])


def shared_log_overlaps(groups: list[list[GaussianMixture]]) -> list[np.ndarray]:
    """:func:`tracking.divergence.log_overlaps` of each group of mixtures, the same numbers
    to the bit, each two mixture objects' block computed once however many groups hold
    both (a neighbour's estimate is one object at every co-hosted receiver:
    :class:`peers.host_parts.SharedDecode`; on a ring of degree 4 about a third of a
    host's blocks are shared). ``L[I, J]`` is the log-sum-exp of its block's pair terms
    (:func:`tracking.divergence.pair_terms`: per pair, either order the same to the bit),
    summed over ``I``'s components first, then ``J``'s, as there (``np.add.reduceat``
    segments); so a block's value depends on its two mixtures alone. Groups with a mixture
    of another dimension than the first non-empty one's, or beyond one block of pairs
    (:data:`tracking.divergence.BLOCK_PAIRS`), by :func:`log_overlaps_many`."""
    out: list = [None] * len(groups)
    seen: dict[int, tuple[int, int]] = {}  # id -> (its index, or -1 empty, -2 other dim; size)
    uniq: list[GaussianMixture] = []
    by_n: dict[int, tuple[list[int], list[list[int]]]] = {}
    rest, dim = [], None
    for g, mixes in enumerate(groups):
        us, C = [], 0
        for D in mixes:
            v = seen.get(id(D))  # the objects are held by the requests meanwhile
            if v is None:
                c = len(D.weights)
                if c and dim is None:
                    dim = D.means.shape[1]  # the first non-empty mixture's
                if not c:
                    v = (-1, 0)
                elif D.means.shape[1] != dim:
                    v = (-2, c)
                else:
                    v = (len(uniq), c)
                    uniq.append(D)
                seen[id(D)] = v
            us.append(v[0])
            C += v[1]
        if C == 0 or C * C > BLOCK_PAIRS or -2 in us:
            rest.append(g)
            continue
        gs, rows = by_n.setdefault(len(us), ([], []))
        gs.append(g)
        rows.append(us)
    if rest:
        for g, L in zip(rest, log_overlaps_many([groups[g] for g in rest]), strict=True):
            out[g] = L
    if not by_n:
        return out
    U = len(uniq)
    size = np.array([len(D.weights) for D in uniq])
    first = size.cumsum() - size  # each mixture's first component
    stacks = []
    for n, (gs, rows) in by_n.items():
        u = np.array(rows, dtype=np.intp).reshape(len(gs), n)
        ok = (u[:, :, None] >= 0) & (u[:, None, :] >= 0)  # (g, n, n)
        stacks.append((gs, ok, (u[:, :, None] * U + u[:, None, :])[ok]))
    blocks, where = np.unique(np.concatenate([k for _, _, k in stacks]), return_inverse=True)
    value = _block_values(uniq, size, first, blocks // U, blocks % U)  # (I inner, J outer)
    lo = 0
    for gs, ok, k in stacks:
        L = np.full(ok.shape, -np.inf)  # empty mixtures: -inf rows and columns
        L[ok] = value[where[lo:lo + len(k)]]
        lo += len(k)
        for g, Lg in zip(gs, L, strict=True):
            out[g] = Lg
    return out


def _block_values(uniq: list[GaussianMixture], size: np.ndarray, first: np.ndarray,
                  I: np.ndarray, J: np.ndarray) -> np.ndarray:
    """``log int D_I D_J`` of each ordered pair ``(I[o], J[o])`` of mixtures of ``uniq``
    (``size``: their components, ``first``: where each one's start in the stacked
    components): the pair terms of each unordered pair once, then per block the
    log-sum-exp as :func:`tracking.divergence.log_overlaps` makes it (per component of
    ``J``, the sum over ``I``'s; then over ``J``'s)."""
    lw = np.concatenate([D.weights for D in uniq])
    m = np.concatenate([D.means for D in uniq])
    P = np.concatenate([D.covs for D in uniq])
    with np.errstate(divide="ignore"):
        lw = np.log(lw)
    x, y = np.minimum(I, J), np.maximum(I, J)  # each unordered pair's terms once
    U = len(uniq)
    pairs, back = np.unique(x * U + y, return_inverse=True)
    px, py = pairs // U, pairs % U
    n = size[px] * size[py]  # its terms, x's component major
    base = n.cumsum() - n
    t = np.arange(int(n.sum())) - base.repeat(n)
    a = first[px].repeat(n) + t // size[py].repeat(n)
    b = first[py].repeat(n) + t % size[py].repeat(n)
    inv, det = inv_det_spd((P[a] + P[b])[None])
    g = lw[a] + lw[b] + log_gaussian((m[a] - m[b])[None], inv, det)[0]
    # each ordered block's terms, a row per component r of J, its columns I's components c
    mI, mJ = size[I], size[J]
    nb = mI * mJ
    ob = nb.cumsum() - nb
    t = np.arange(int(nb.sum())) - ob.repeat(nb)
    r, c = t // mI.repeat(nb), t % mI.repeat(nb)
    swap = (I > J).repeat(nb)  # stored as (J's component, I's): row-major already
    idx = base[back].repeat(nb) + np.where(swap, r * mI.repeat(nb) + c,
                                           c * mJ.repeat(nb) + r)
    terms = g[idx]
    top = np.maximum.reduceat(terms, ob)
    safe = np.where(np.isfinite(top), top, 0.0)
    rows = mJ.cumsum() - mJ  # each block's first row
    starts = ob.repeat(mJ) + (np.arange(int(mJ.sum())) - rows.repeat(mJ)) * mI.repeat(mJ)
    S = np.add.reduceat(np.add.reduceat(np.exp(terms - safe.repeat(nb)), starts), rows)
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(top), safe + np.log(S), -np.inf)


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
    index: dict[int, int] = {}  # each mixture object once (shared by co-hosted receivers)
    uniq: list[GaussianMixture] = []
    lists = []
    for mixes, *_ in group:
        row = []
        for D in mixes:
            u = index.get(id(D))  # the objects are held by the requests meanwhile
            if u is None:
                u = index[id(D)] = len(uniq)
                uniq.append(D)
            row.append(u)
        lists.append(row)
    lens = [len(x) for x in lists]
    out = [np.zeros((z, z)) for z in lens]
    usize = np.array([len(D.weights) for D in uniq], dtype=np.intp)
    fu = np.array([u for x in lists for u in x], dtype=np.intp)  # every (request, input)
    sizes = usize[fu]
    if not sizes.any():
        return out
    full = [D for D in uniq if len(D.weights)]
    ufirst = usize.cumsum() - usize  # each object's first component
    comp = np.repeat(ufirst[fu], sizes) + _ranks(tuple(sizes.tolist()))  # request-major
    req = np.repeat(np.repeat(np.arange(len(group)), lens), sizes)  # per component
    inp = np.repeat(np.arange(len(fu)) - np.repeat(np.cumsum(lens) - lens, lens), sizes)
    W = np.concatenate([D.weights for D in full])[comp]
    keep = np.flatnonzero(W >= min_weight)
    if not len(keep):
        return out
    w = W[keep]
    ck = comp[keep]
    X = np.concatenate([D.means for D in full])[ck][:, pos]
    P = (position_block(np.concatenate([D.covs for D in full])[ck], pos)
         if chi2 is not None else np.zeros((len(keep), 2, 2)))
    counts = np.bincount(req[keep], minlength=len(group))
    owner = inp[keep]
    C = counts[counts > 0]  # each request with targets: its (C, C) pairs, row-major
    t = np.arange(int((C * C).sum())) - np.repeat(np.cumsum(C * C) - C * C, C * C)
    first = np.repeat(np.cumsum(C) - C, C * C)
    a, b = first + t // np.repeat(C, C * C), first + t % np.repeat(C, C * C)
    dP = np.linalg.det(P) if chi2 is not None else None  # per component, not per pair
    close = gated(X[a] - X[b], P[a], P[b], gate, chi2, *((dP[a], dP[b]) if chi2 is not None
                                                          else ()))  # near(), pair by pair
    n = max(lens)
    hit = np.zeros((len(keep), n), bool)  # (C, n): an input's target within the gate
    hit[a[close], owner[b[close]]] = True
    rows = req[keep] * n + owner  # each component's (request, input), in order
    seg = np.flatnonzero(np.concatenate(([True], rows[1:] != rows[:-1])))
    U = np.zeros((len(group) * n, n))
    U[rows[seg]] = unmatched_sums(w, hit, np.diff(np.append(seg, len(rows))).tolist())
    U = U.reshape(len(group), n, n)
    return [U[r, :z, :z] for r, z in enumerate(lens)]


def _offsets(args: list[tuple]) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """``"offsets"``: :func:`peers.trust_checks.offset_information_many` of every request
    (each its own reference; the same ``pos``, ``min_weight``, ``gate``, ``chi2``) at once:
    every component's nearest reference component (the references padded at their end
    with components at infinity, never nearest), gate and inverse in one computation, the
    sums per mixture as there."""
    return _by_key(args, lambda a: (tuple(a[2]), a[3], a[4], a[5]), _offsets_group)


def _offsets_group(group: list[tuple]) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    pos, min_weight, gate, chi2 = group[0][2:]
    # each mixture object once (a neighbour's estimate is one object at all its co-hosted
    # receivers, peers.host_parts.SharedDecode), its components of at least min_weight
    # picked from all of them stacked: the same positions and position blocks
    index: dict[int, int] = {}
    uniq: list[GaussianMixture] = []

    def uid(M: GaussianMixture) -> int:
        u = index.get(id(M))  # the objects are held by the requests meanwhile
        if u is None:
            u = index[id(M)] = len(uniq)
            uniq.append(M)
        return u

    refs = np.array([uid(ref) for ref, *_ in group], dtype=np.intp)
    lists = [[uid(M) for M in mixes] for _, mixes, *_ in group]
    out: list[list] = [[None] * len(x) for x in lists]
    infos = _offsets_found(uniq, refs, lists, pos, min_weight, gate, chi2)
    for r, i, info in infos:
        out[r][i] = info
    return [[(np.zeros((2, 2)), np.zeros(2)) if v is None else v for v in row] for row in out]


def _offsets_found(uniq: list[GaussianMixture], refs: np.ndarray, lists: list[list[int]],
                   pos: list[int], min_weight: float, gate: float, chi2: float | None
                   ) -> list[tuple[int, int, tuple[np.ndarray, np.ndarray]]]:
    """:func:`_offsets_group`'s ``(request, mixture, (I, y))`` of the mixtures whose
    components matched their request's reference (``refs[r]``, ``lists[r]``: indices into
    ``uniq``): every component's nearest reference component (the references padded at
    their end with components at infinity, never nearest), gate and inverse at once, the
    sums per mixture as :func:`peers.trust_checks.offset_information_many` makes them."""
    sizes = np.array([len(M.weights) for M in uniq], dtype=np.intp)
    if not sizes.any():
        return []
    full = [M for M in uniq if len(M.weights)]
    keep = np.concatenate([M.weights for M in full]) >= min_weight
    cnt = np.bincount(np.repeat(np.arange(len(uniq)), sizes)[keep], minlength=len(uniq))
    kidx = np.flatnonzero(keep)  # the target components, mixture by mixture
    kst = cnt.cumsum() - cnt  # each mixture's first in kidx
    X = np.concatenate([M.means for M in full])[kidx][:, pos]
    P = position_block(np.concatenate([M.covs for M in full])[kidx], pos)
    lens = [len(x) for x in lists]
    fu = np.array([u for x in lists for u in x], dtype=np.intp)
    fr = np.repeat(np.arange(len(lists)), lens)
    fi = np.arange(len(fu)) - np.repeat(np.cumsum(lens) - lens, lens)
    c = cnt[fu]
    valid = (c > 0) & (cnt[refs][fr] > 0)  # a reference with targets, a mixture with some
    if not valid.any():
        return []
    su, sr, si, sc = fu[valid], fr[valid], fi[valid], c[valid]
    req, t = np.unique(sr, return_inverse=True)  # the requests with work, in order
    tb = cnt[refs[req]]
    mb = np.full((len(req), int(tb.max()), 2), np.inf)  # (g, m, 2): padded at infinity
    Pb = np.zeros((len(req), int(tb.max()), 2, 2))
    at = np.repeat(np.arange(len(req)), tb), _ranks(tuple(tb.tolist()))
    src = np.repeat(kst[refs[req]], tb) + at[1]
    mb[at] = X[src]
    Pb[at] = P[src]
    counts = sc.tolist()
    comp = np.repeat(kst[su], sc) + _ranks(tuple(counts))
    rows = np.repeat(t, sc)
    ma, Pa = X[comp], P[comp]  # (n, 2), (n, 2, 2)
    diff = ma[:, None, :] - mb[rows]  # (n, top, 2)
    nearest = np.argmin(np.linalg.norm(diff, axis=2), axis=1)
    d = diff[np.arange(len(ma)), nearest]
    Pn = Pb[rows, nearest]
    ok = gated(d, Pa, Pn, gate, chi2)
    if not ok.any():
        return []
    hits = np.add.reduceat(ok, np.cumsum([0, *counts[:-1]])).tolist()  # gated per mixture
    infos = information_sums(Pa[ok] + Pn[ok], d[ok], hits)  # every mixture's at once
    return [(r, i, info) for r, i, info in zip(sr.tolist(), si.tolist(), infos, strict=True)
            if info is not None]


_CONFIGS: dict = {}
"""Each distinct :class:`TrustConfig` value seen, to its number (:func:`_config_key`)."""
_CONFIG_OF: dict[int, tuple] = {}
"""``id(cfg)`` to ``(cfg, its number)``: a frozen dataclass hashes and compares all its
fields each time (some 50), which a host's requests did per request."""


def _config_key(cfg) -> int:
    """A number equal for equal configs (grouping the requests that stack together), looked
    up by the object's identity after its first time (the object kept, so its id is not
    reused while it is here; a host has one config object a peer)."""
    v = _CONFIG_OF.get(id(cfg))
    if v is not None and v[0] is cfg:
        return v[1]
    if len(_CONFIG_OF) > 4096:  # many short-lived configs (tests): start again
        _CONFIG_OF.clear()
        _CONFIGS.clear()
    n = _CONFIGS.setdefault(cfg, len(_CONFIGS))
    _CONFIG_OF[id(cfg)] = (cfg, n)
    return n


def _tests(args: list[tuple]) -> list[list[float]]:
    """``"tests"``: :func:`peers.trust_checks.neighbour_tests` of every request (the same
    config and number of inputs) at once: :func:`peers.trust_checks.neighbour_tests_many`
    of them stacked (every peer's neighbours in one computation, the one formula)."""
    def many(group: list[tuple]) -> list[list[float]]:
        def stack(i: int) -> np.ndarray | None:  # np.array: np.stack's values, less setup
            return None if group[0][i] is None else np.array([a[i] for a in group], float)
        return neighbour_tests_many(group[0][0], *(stack(i) for i in range(1, 7))).tolist()
    return _by_key(args, lambda a: (_config_key(a[0]), len(a[6]), a[2] is None, a[5] is None),
                   many)


def _own_tests(args: list[tuple]) -> list[list[float]]:
    """``"own_tests"``: :func:`peers.trust_checks.own_tests_many` of every request (the same
    config and number of inputs) stacked."""
    def many(group: list[tuple]) -> list[list[float]]:
        L0 = None if group[0][2] is None else np.stack([a[2] for a in group])
        return own_tests_many(group[0][0], np.stack([a[1] for a in group]), L0,
                              np.array([a[3] for a in group], float),
                              np.array([a[4] for a in group], float)).tolist()
    return _by_key(args, lambda a: (_config_key(a[0]), len(a[3]), a[2] is None), many)


def _masses(args: list[tuple]) -> list[tuple[list[float], list[float]]]:
    """``"masses"``: each mixture's mass and target mass, computed once per mixture object
    however many peers' requests hold it (a neighbour's estimate is one object at every
    co-hosted receiver: :class:`peers.host_parts.SharedDecode`), the sums of the mixtures
    of 1 to :data:`SHORT` components in two stacked sums (:func:`_mass_values`), the others
    by the same functions one by one."""
    seen: dict[tuple[int, float], int] = {}
    uniq: list[tuple[GaussianMixture, float]] = []
    rows = []
    for mixes, min_weight in args:
        row = []
        for D in mixes:
            key = (id(D), min_weight)  # the objects are held by the requests meanwhile
            u = seen.get(key)
            if u is None:
                u = seen[key] = len(uniq)
                uniq.append((D, min_weight))
            row.append(u)
        rows.append(row)
    values = _mass_values(uniq)
    return [([values[u][0] for u in row], [values[u][1] for u in row]) for row in rows]


SHORT = 7
"""Mixtures of at most this many components have their masses summed stacked
(:func:`_mass_values`): NumPy sums fewer than 8 numbers one after the other (``a.sum()``
is then ``((a_0 + a_1) + a_2) + ...``), which :func:`peers.trust_checks.segment_sums`
does (padded with ``-0.0``, which added changes no number); 8 or more it sums pairwise."""


def _mass_values(uniq: list[tuple[GaussianMixture, float]]) -> list[tuple[float, float]]:
    """Each ``(mixture, min_weight)``'s ``(mass, target_mass)`` (``D.mass``,
    :func:`peers.trust_checks.target_mass`, to the bit): those of 1 to :data:`SHORT`
    components together (the weights concatenated; the masses by segments, the target
    masses by segments of the weights kept), the others one by one."""
    out: list = [None] * len(uniq)
    short = []
    for u, (D, min_weight) in enumerate(uniq):
        if 0 < len(D.weights) <= SHORT:
            short.append(u)
        else:
            out[u] = (D.mass, target_mass(D, min_weight))
    if not short:
        return out
    sizes = [len(uniq[u][0].weights) for u in short]
    W = np.concatenate([uniq[u][0].weights for u in short])
    keep = W >= np.repeat([uniq[u][1] for u in short], sizes)
    kept = np.add.reduceat(keep, np.cumsum([0, *sizes[:-1]]), dtype=np.intp).tolist()
    mass = segment_sums(W, sizes).tolist()
    tops = segment_sums(W[keep], kept).tolist() if any(kept) else [0.0] * len(short)
    for n, u in enumerate(short):  # an empty segment's sum is -0.0, target_mass's 0.0
        out[u] = (mass[n], tops[n] if kept[n] else 0.0)
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
