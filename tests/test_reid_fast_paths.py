"""tracking.reidentify's short cuts (the 50-peer CPU work, issue 33): ``_returns`` computes a
distance only for labels that may return far (dark at the last scan, or any when a track of the
last scan lost its label), ``_forget`` tests only tracks published long enough to be lost, and
the labels' keys are computed once per scan. Checked here against the rule as the docstring
states it (every known label's distance, then the dark-or-took filter) on random sequences of
tracks that go dark, come back far, swap and take each other's labels and are stamped new: the
same labels out, the same memory, to the bit."""

from __future__ import annotations

import numpy as np
from sensornet.tracking.label_keys import keys_find, keys_isin, label_keys, replace_labels
from sensornet.tracking.labels import PUBLISHED_BASE, new_labels
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reidentify import REJECTED_BASE, Reidentification

CV = ConstantVelocity(T=1.0, sigma_w=5.0)
OWN = 3


class Reference(Reidentification):
    """``_returns`` as its docstring states it, without the short cut."""

    def _returns(self, labels, lab, m, P, new, k):
        L, keys, K, M = self._last
        if not len(keys) or not len(lab):
            return labels, lab, new
        own = label_keys(lab)
        found, pos = keys_find(keys, own)
        rows = np.flatnonzero(~new & found)
        if not len(rows):
            return labels, lab, new
        far = self._distance(m[rows], K[pos[rows]], M[pos[rows]], k, pairs=False) > self.jump
        rows = rows[far]
        if len(rows) and self._on is not None and self._on[0] == k - 1:
            k0, lab0, m0, P0 = self._on[:4]
            gone = np.flatnonzero(~keys_isin(label_keys(lab0), own))
            took = np.zeros(len(rows), dtype=bool)
            if len(gone):
                took = (self._costs(m[rows], P[rows], lab0[gone], np.full(len(gone), k0),
                                    m0[gone], P0[gone], k) <= self.gate).any(axis=1)
            rows = rows[(K[pos[rows]] < k - 1) | took]
        if not len(rows):
            return labels, lab, new
        stamp = new_labels(self.origin, k, len(rows), PUBLISHED_BASE + REJECTED_BASE)
        labels = replace_labels(labels, lab[rows], stamp)
        lab = lab.copy()
        lab[rows] = stamp
        new = new.copy()
        new[rows] = True
        return labels, lab, new


def _scans(rng, n_scans=40, n_tracks=5):
    """Random labelled mixtures: tracks moving at CV, each scan published or light, now and
    then jumping kilometres, taking another track's label, or stamped new (own, this scan)."""
    x = np.column_stack([rng.uniform(-3e3, 3e3, n_tracks), rng.normal(0, 20, n_tracks),
                         rng.uniform(-3e3, 3e3, n_tracks), rng.normal(0, 20, n_tracks)])
    lab = np.array([[OWN, 0, PUBLISHED_BASE + i] for i in range(n_tracks)], dtype=np.int64)
    for k in range(1, n_scans):
        x = x @ CV.F.T
        u = rng.random(n_tracks)
        x[u < 0.05, 0] += rng.choice([-1, 1]) * rng.uniform(3.5e3, 8e3)  # a far return
        if rng.random() < 0.15:  # one track takes another's label (a merge)
            i, j = rng.choice(n_tracks, 2, replace=False)
            lab[i] = lab[j]
        fresh = np.flatnonzero(rng.random(n_tracks) < 0.08)  # stamped new this scan
        lab[fresh] = new_labels(OWN, k, len(fresh), PUBLISHED_BASE)
        w = np.where(rng.random(n_tracks) < 0.75, rng.uniform(0.6, 1.0, n_tracks),
                     rng.uniform(0.0, 0.4, n_tracks))
        covs = np.tile(np.eye(4) * rng.uniform(100.0, 4e4), (n_tracks, 1, 1))
        yield k, lab.copy(), GaussianMixture(w, x.copy(), covs)


def test_short_cuts_give_the_rule_as_stated():
    hits = {"restamped": 0, "reidentified": 0}
    for seed in range(40):
        fast = Reidentification(CV, OWN, scans=4)
        ref = Reference(CV, OWN, scans=4)
        for k, lab, mix in _scans(np.random.default_rng(seed)):
            a = fast.apply(lab, mix, 0.5, k)
            b = ref.apply(lab, mix, 0.5, k)
            assert a.tobytes() == b.tobytes(), (seed, k)
            hits["restamped"] += int((a[:, 2] >= PUBLISHED_BASE + REJECTED_BASE).any()
                                     & (a[:, 1] == k).any())
            hits["reidentified"] += int((~(a == lab).all(axis=1)
                                         & (a[:, 2] < PUBLISHED_BASE + REJECTED_BASE)).any())
            for f in ("_lost", "_last"):
                x, y = getattr(fast, f), getattr(ref, f)
                assert (x is None) == (y is None)
                if x is not None:
                    assert all(p.tobytes() == q.tobytes() for p, q in zip(x, y, strict=True))
    assert hits["restamped"] > 20 and hits["reidentified"] > 20, hits  # both paths ran


class General(Reidentification):
    """:meth:`Reidentification.apply` without the unchanged-tracks short cut."""

    def _unchanged(self, lab, new, k):
        return False


def _steady(rng, n_scans=60, n_tracks=4):
    """Labelled mixtures whose published set mostly stays as it was (the usual scan), now and
    then a track going dark for a few scans, coming back, or stamped new; light remnants
    carrying dark labels, so the memory holds more than the published tracks."""
    x = np.column_stack([rng.uniform(-3e3, 3e3, n_tracks), rng.normal(0, 20, n_tracks),
                         rng.uniform(-3e3, 3e3, n_tracks), rng.normal(0, 20, n_tracks)])
    lab = np.array([[OWN, 0, PUBLISHED_BASE + i] for i in range(n_tracks)], dtype=np.int64)
    dark = np.zeros(n_tracks, dtype=int)
    for k in range(1, n_scans):
        x = x @ CV.F.T
        if rng.random() < 0.1:
            dark[rng.integers(n_tracks)] = rng.integers(1, 6)  # dark for a few scans
        if rng.random() < 0.05:
            i = rng.integers(n_tracks)
            lab[i] = new_labels(OWN, k, 1, PUBLISHED_BASE)[0]
        w = np.where(dark > 0, rng.uniform(0.0, 0.4, n_tracks), rng.uniform(0.6, 1.0, n_tracks))
        dark = np.maximum(dark - 1, 0)
        covs = np.tile(np.eye(4) * 400.0, (n_tracks, 1, 1))
        yield k, lab.copy(), GaussianMixture(w, x.copy(), covs)


class Counted(Reidentification):
    """:class:`Reidentification`, counting the scans that took the short cut."""

    taken = 0

    def _same_tracks(self, *args):
        self.taken += 1
        return super()._same_tracks(*args)


def test_unchanged_tracks_short_cut_gives_the_general_path():
    """The unchanged-tracks short cut (``_same_tracks``, taken on most scans of a 50-peer
    network) against the general path: the same labels and memory (published tracks and
    their runs, lost and last-published sets) to the bit, on steady sequences and on the
    random ones above; the short cut taken on most steady scans."""
    taken = scans = 0
    for seed in range(30):
        for gen in (_steady, _scans):
            fast, ref = Counted(CV, OWN, scans=4), General(CV, OWN, scans=4)
            for k, lab, mix in gen(np.random.default_rng(seed)):
                a, b = fast.apply(lab, mix, 0.5, k), ref.apply(lab, mix, 0.5, k)
                assert a.tobytes() == b.tobytes(), (seed, gen.__name__, k)
                for f in ("_on", "_lost", "_last"):
                    x, y = getattr(fast, f), getattr(ref, f)
                    assert (x is None) == (y is None)
                    if x is not None:
                        assert all(np.asarray(p).tobytes() == np.asarray(q).tobytes()
                                   and np.asarray(p).dtype == np.asarray(q).dtype
                                   for p, q in zip(x, y, strict=True)), (seed, k, f)
                scans += gen is _steady
            if gen is _steady:
                taken += fast.taken
    assert taken > scans // 2, (taken, scans)
