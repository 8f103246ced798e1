"""A GM-PHD peer's label bookkeeping (tracking.reidentify, Publication in
tracking.label_confirmation, SupportRule.keep) compares label keys with tracking.label_keys'
byte compares and column lexsorts, not NumPy's structured-key paths (np.isin, np.unique,
searchsorted, ==), for speed (docs/labelled-tracking.md, "50 peers"). Checked here to the bit,
both sides in one run: the twin of a labelled GM-PHD network whose targets are often lost and
re-born (Pd 0.8) publishes the same bytes with NumPy's reference paths patched in."""

from __future__ import annotations

import numpy as np
import pytest
import sensornet.tracking.label_confirmation as lc
import sensornet.tracking.reidentify as reid
import sensornet.tracking.support as support
from sensornet.peers.core import Publish
from sensornet.sim.run import twin as twinmod
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.label_keys import label_keys
from sensornet.tracking.models import ConstantVelocity


def _isin(a, b):
    return np.isin(a, b)


def _find(table, keys):
    pos = np.searchsorted(table, keys).clip(max=table.size - 1)
    return table[pos] == keys, pos


def _equal(a, b):
    return a == b


def _key_order(labels):
    return np.argsort(label_keys(labels))


def _unique_first(labels):
    return np.unique(label_keys(labels), return_index=True)


def _transitions(self, gaps, which=2):
    steps, inv = np.unique(gaps, return_inverse=True)
    FQ = [self.motion.transition(int(s)) for s in steps]
    return [np.stack([fq[i] for fq in FQ])[inv] for i in range(which)]


def _published(scn, monkeypatch) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {n: [] for n in scn.sensor_names}
    carry = twinmod._Clock.carry_out

    def carry_out(self, t, sender, outputs):
        out[sender] += [o.channel.encode() + o.payload for o in outputs
                        if isinstance(o, Publish)]
        return carry(self, t, sender, outputs)

    with monkeypatch.context() as m:
        m.setattr(twinmod._Clock, "carry_out", carry_out)
        run_twin(scn, 0, batch=True)
    return out


@pytest.fixture(scope="module")
def scn(tmp_path_factory):
    path = tmp_path_factory.mktemp("keys") / "net6.toml"
    path.write_text(network_scenario(6, 2, 40, rounds=2, detection_probability=0.8))
    return load_scenario(str(path))


def test_reference_key_paths_publish_the_same_bytes(scn, monkeypatch):
    fast = _published(scn, monkeypatch)
    with monkeypatch.context() as m:
        for mod in (reid, lc, support):
            for name, f in (("keys_isin", _isin), ("keys_find", _find),
                            ("keys_equal", _equal)):
                if hasattr(mod, name):
                    m.setattr(mod, name, f)
        m.setattr(reid, "_key_order", _key_order)
        m.setattr(lc, "_unique_first", _unique_first)
        m.setattr(reid.Reidentification, "_transitions", _transitions)
        slow = _published(scn, monkeypatch)
    assert sum(len(v) for v in fast.values()) > 6 * 40 * 2  # estimates and tracks
    for name in scn.sensor_names:
        assert fast[name] == slow[name], name


def test_unique_first_is_numpy_unique_with_first_rows():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(0, 25))
        labels = rng.integers(0, 4, (n, 3)).astype(np.int64)
        labels[:, 2] += rng.integers(0, 2, n) << 36
        keys, rows = lc._unique_first(labels)
        ref_keys, ref_rows = np.unique(label_keys(labels), return_index=True)
        assert keys.tobytes() == ref_keys.tobytes() and np.array_equal(rows, ref_rows)


def test_transitions_are_the_stacked_model_transitions():
    r = reid.Reidentification(ConstantVelocity(sigma_w=2.0), 1)
    for gaps in ([1, 1, 1], [3], [1, 2, 1, 4], [0, 0]):
        g = np.array(gaps)
        F, Q = r._transitions(g)
        F1, Q1 = _transitions(r, g)
        assert F.flags.c_contiguous and np.array_equal(F, F1) and np.array_equal(Q, Q1)


def test_present_above_is_numpy_unique_and_isin():
    """Confirmation.observe's labels present and heavy: np.unique of the keys and np.isin of
    them in the heavy rows' keys (ties of keys, empty mixtures, nothing heavy)."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        n = int(rng.integers(0, 25))
        labels = rng.integers(0, 4, (n, 3)).astype(np.int64)
        labels[:, 2] += rng.integers(0, 2, n) << 36
        w = rng.uniform(0.0, 1.0, n)
        keys, above = lc._present_above(labels, w, 0.5)
        ref = np.unique(label_keys(labels))
        assert keys.tobytes() == ref.tobytes()
        assert np.array_equal(above, np.isin(ref, label_keys(labels)[w > 0.5]))
