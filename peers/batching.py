"""Consensus fusions of several peers deferred to one stacked computation (a peer host's).

A peer host (:mod:`peers.host`) steps many peers in one loop; in one pass, many of them get
the last input of a consensus round. Fusing each at once costs one small array computation
per peer, paid mostly in per-call overhead (a hybrid fusion of five inputs of a few
components each: ~60 NumPy calls). With a :class:`FusionBatch` set on their
:class:`peers.consensus.Consensus`, a round that is ready becomes a :class:`FusionJob`
instead; the host runs every job of the pass at the end of it (:meth:`FusionBatch.run`,
jobs of fusers with the same ``batch_key`` through one ``fuse_many``), and each consensus
then continues exactly as if its fusion had just returned: the round's records, the next
round's estimate or the tracks, the rounds now complete (:meth:`Consensus.complete`).

Whatever needs a round's result at once (the next scan, the end of the run, a peer
stopping) settles its job on the spot with the fuser's own ``fuse``; the batch then skips it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sensornet.peers.contracts import FusionInput
from sensornet.peers.labelling_batch import label_fused_many
from sensornet.peers.tracks_batch import masses_many
from sensornet.peers.trust_batch import weigh_together


@dataclass(eq=False)
class FusionJob:
    """One consensus round waiting for its fusion."""

    consensus: Any
    """The :class:`peers.consensus.Consensus` it belongs to."""
    state: Any
    """Its scan state (:class:`peers.consensus_types.ScanState`) when the round was queued."""
    input: FusionInput
    senders: list[str]
    forced: bool = False
    """The scan's deadline passed: run its remaining rounds with what arrived."""
    trust: tuple | None = None
    """The round's trust test still to run (``input`` None until it has): the arguments of
    its :meth:`peers.trust.Trust.weigh` and the round's inputs
    (:meth:`peers.consensus_batch.BatchedRounds.tested`); the batch runs every job's
    together (:func:`peers.trust_batch.weigh_together`)."""
    settled: bool = False
    """Fused already (settled on the spot) or cancelled: the batch skips it."""


@dataclass
class FusionBatch:
    """The jobs of one host pass; :meth:`run` fuses them and lets each consensus go on."""

    jobs: list[FusionJob] = field(default_factory=list)
    stacked: int = 0
    """Jobs fused through a ``fuse_many`` with at least one other (for the summary)."""
    runs: int = 0
    trust_together: bool = True
    """The jobs' trust tests together (:func:`peers.trust_batch.weigh_together`); False:
    each on its own (:meth:`peers.trust.Trust.weigh`, the same numbers: to compare)."""

    label_together: bool = True
    """The fused densities' labels of labelled peers together
    (:func:`peers.labelling_batch.label_fused_many`); False: each in its own completion
    (the same labels: to compare)."""

    labelled: int = 0
    """Rounds whose fused density was labelled together with another's (for tests)."""
    tracks_together: bool = True
    """The input masses of the last rounds' tracks together
    (:func:`peers.tracks_batch.masses_many`); False: each peer's own (the same numbers)."""
    extracted: int = 0
    """Last rounds whose tracks' input masses were computed together (for tests)."""

    def add(self, job: FusionJob) -> None:
        self.jobs.append(job)

    def run(self, now: float) -> list:
        """Fuse every waiting job and complete it at wall time ``now``; returns the
        consensus objects that completed one (each once, in order). Jobs a completion queues
        (the next round of a scan whose deadline passed) wait for the next call."""
        jobs, self.jobs = [j for j in self.jobs if not j.settled], []
        if not jobs:
            return []
        self.runs += 1
        results: dict[int, tuple[object, Exception | None]] = {}
        tested = [j for j in jobs if j.trust is not None]
        if tested:  # every round's trust test at once, then each job's inputs
            calls = [(j.consensus.trust, *j.trust[0]) for j in tested]
            weights = weigh_together(calls) if self.trust_together else [
                _alone(trust, args) for trust, *args in calls]
            for j, w in zip(tested, weights, strict=True):
                exc = j.consensus.tested(j, w)
                if exc is not None:
                    results[id(j)] = (None, exc)
        groups: dict[object, list[FusionJob]] = {}
        for j in jobs:
            if id(j) not in results:
                groups.setdefault(j.consensus.fuser_hooks.batch_key, []).append(j)
        for group in groups.values():
            fused = None
            if len(group) > 1:
                try:
                    fused = group[0].consensus.fuser_hooks.fuse_many([j.input for j in group])
                    self.stacked += len(group)
                except Exception:  # noqa: BLE001 - each on its own below, with its own error
                    fused = None
            for n, j in enumerate(group):
                if fused is not None:
                    results[id(j)] = (fused[n], None)
                    continue
                try:
                    results[id(j)] = (j.consensus.fuser.fuse(j.input), None)
                except Exception as exc:  # the consensus counts it, as its own fusion would
                    results[id(j)] = (None, exc)
        labelled = _label_together(jobs, results) if self.label_together else {}
        self.labelled += len(labelled)
        masses = _masses_together(jobs, results) if self.tracks_together else {}
        self.extracted += len(masses)
        done, seen = [], set()
        for j in jobs:  # in the order the rounds became ready
            if j.settled:  # a completion before settled it (cannot, but cheap to honour)
                continue
            mix, exc = results[id(j)]
            j.consensus.complete(j, mix, exc, now, labelled.get(id(j)), masses.get(id(j)))
            if id(j.consensus) not in seen:
                seen.add(id(j.consensus))
                done.append(j.consensus)
        return done


def _problems(jobs: list[FusionJob], results: dict,
              problem_of) -> list[tuple[FusionJob, object]]:
    """``(job, problem)`` for the jobs about to complete whose consensus is labelled and
    waits for them (one job per consensus: each works from its own state, untouched by the
    others' completions), ``problem_of(consensus, state, mix)`` where it gives one."""
    todo, seen = [], set()
    for j in jobs:
        c = j.consensus
        mix, exc = results[id(j)]
        if exc is not None or not getattr(c, "labelled", False) or id(c) in seen:
            continue
        seen.add(id(c))
        if not c.waiting(j):
            continue
        problem = problem_of(c, j.state, mix)
        if problem is not None:
            todo.append((j, problem))
    return todo


def _label_together(jobs: list[FusionJob], results: dict) -> dict[int, object]:
    """The labels of the fused densities of the jobs about to complete whose consensus
    labels them (one job per consensus: each labels with its own state, untouched by the
    others' completions), computed together: ``{id(job): FusedLabels}``; nothing if fewer
    than two, or if the stacked computation raised (each then labels its own, as before)."""
    todo = _problems(jobs, results, lambda c, state, mix: c.label_problem(state, mix))
    if len(todo) < 2:
        return {}
    try:
        got = label_fused_many([p for _, p in todo])
    except Exception:  # noqa: BLE001 - each completion labels its own and meets its error
        return {}
    return {id(j): g for (j, _), g in zip(todo, got, strict=True)}


def _masses_together(jobs: list[FusionJob], results: dict) -> dict[int, tuple]:
    """The input masses of the tracks the jobs about to complete will extract (one job per
    consensus, each by its own state), computed together: ``{id(job): (masses, supports,
    means)}``; nothing if fewer than two, or where the stacked computation declined."""
    todo = _problems(jobs, results, lambda c, state, mix: c.tracks_problem(state, mix))
    if len(todo) < 2:
        return {}
    try:
        got = masses_many([p for _, p in todo])
    except Exception:  # noqa: BLE001 - each peer computes its own and meets its error
        return {}
    return {id(j): (*g, p[0]) for (j, p), g in zip(todo, got, strict=True) if g is not None}


def _alone(trust, args: list):
    """``trust.weigh(*args)``, or the exception it raised (as :func:`weigh_together` gives)."""
    try:
        return trust.weigh(*args)
    except Exception as exc:  # noqa: BLE001 - that round failed, as in the batch
        return exc


def prepare_local_steps(scans: list[tuple[Any, Any, bytes]]) -> list:
    """The local steps of several co-hosted peers' coming scans, computed together.

    ``scans``: ``(core, key, payload)`` of scan messages about to be handled (``key``, or the
    route its transport parsed from it, :meth:`PeerCore.scan_step`), each by its
    :class:`peers.core.PeerCore`. The peers whose estimator can prepare steps together
    (``prepare_many``, e.g. :class:`peers.estimators.GmphdEstimator`: one stacked GM-PHD
    predict, update and reduction) get them prepared; their own step then takes the prepared
    result if it is the step they make (:meth:`PeerCore.scan_step` guesses it). Nothing else
    changes: the messages are handled as before, in the same order. Returns the cores whose
    steps were prepared.
    """
    groups: dict[type, tuple[list, list, list, list]] = {}
    seen: set[int] = set()
    for core, key, payload in scans:
        est = core.consensus.estimator
        prep = getattr(type(est), "prepare_many", None)
        if prep is None or id(core) in seen:
            continue
        try:
            step = core.scan_step(key, payload)
        except Exception:  # noqa: BLE001 - the peer's own receive meets it, as always
            step = None
        if step is None:
            continue
        seen.add(id(core))
        cores, ests, steps, zs = groups.setdefault(type(est), ([], [], [], []))
        cores.append(core)
        ests.append(est)
        steps.append(step[0])
        zs.append(step[1])
    done: list = []
    for cls, (cores, ests, steps, zs) in groups.items():
        if len(ests) > 1:
            try:
                cls.prepare_many(ests, steps, zs)
            except Exception:  # noqa: BLE001 - nothing prepared: each peer's own step runs
                continue       # (and meets, counts and scores its own error, as always)
            done += cores
    return done
