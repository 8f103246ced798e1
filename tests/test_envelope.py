"""Signed messages (secure mode), without Zenoh: the envelope, the roster, and a peer's transport
callback counting what it refuses (``unauthenticated``, ``replayed``) before any decoding.

The same against real processes: tests/test_attacks_signed.py.
"""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from sensornet.peers.security import Security, SecurityError, load_roster, make_keys
from sensornet.peers.transport import Transport
from sensornet.protocol import envelope
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.envelope import TRAILER, Signer, inner, owner
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Scan
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture

NET = "signet"
PEERS = ("s1", "s2", "s3")
K = Keys(NET)


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    d = tmp_path_factory.mktemp("keys")
    make_keys(NET, ["world", *PEERS], d)
    return d


@pytest.fixture(scope="module")
def signers(keys):
    return {m: Security.load(keys, m, NET, PEERS).signer() for m in ["world", *PEERS]}


@pytest.fixture()
def verifier(keys):
    return Security.load(keys, "s1", NET, PEERS).verifier()


def _estimate(sender="s2", k=3, rnd=0) -> bytes:
    mix = GaussianMixture(np.array([0.9]), np.array([[1.0, 2.0, 0.5, -0.5]]),
                          np.eye(4)[None] * 4.0)
    return encode(Estimate(sender, k, mix, round=rnd, seq=k, send_time=1.5))


def test_keys_write_signing_keys_and_the_roster(keys, tmp_path):
    roster = json.loads((keys / "members.json").read_text())["ed25519"]
    assert set(roster) == {"world", *PEERS}
    for m in ["world", *PEERS]:
        path = keys / f"{m}.ed25519"
        assert path.stat().st_mode & 0o077 == 0  # private: owner only
        assert path.read_bytes().startswith(b"-----BEGIN PRIVATE KEY-----")
    # the roster entry is what openssl prints between the PEM markers of the public key
    from cryptography.hazmat.primitives import serialization

    pem = serialization.load_pem_private_key((keys / "s1.ed25519").read_bytes(), None) \
        .public_key().public_bytes(serialization.Encoding.PEM,
                                   serialization.PublicFormat.SubjectPublicKeyInfo)
    assert "".join(pem.decode().splitlines()[1:-1]) == roster["s1"]
    assert len(base64.b64decode(roster["s1"])) == 44  # DER SubjectPublicKeyInfo, Ed25519
    # a folder made before signing keys existed gets them on the next run, TLS keys kept
    old = tmp_path / "old"
    make_keys(NET, ["world", "s1"], old)
    tls = (old / "s1.key").read_bytes()
    (old / "s1.ed25519").unlink()
    data = json.loads((old / "members.json").read_text())
    del data["ed25519"]
    (old / "members.json").write_text(json.dumps(data))
    with pytest.raises(SecurityError, match="no message-signing key s1.ed25519"):
        Security.load(old, "s1", NET, ["s1"]).signer()
    make_keys(NET, ["world", "s1"], old)
    assert (old / "s1.key").read_bytes() == tls
    assert set(load_roster(old)) == {"world", "s1"}
    Security.load(old, "s1", NET, ["s1"]).signer()
    # rotation: a new signing key, the roster follows
    before = load_roster(old)["s1"]
    make_keys(NET, ["s1"], old, overwrite=True)
    assert envelope_bytes(load_roster(old)["s1"]) != envelope_bytes(before)
    assert set(load_roster(old)) == {"world", "s1"}


def envelope_bytes(public_key) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


def test_a_key_that_is_not_the_rosters_is_refused_at_start(keys, tmp_path):
    import shutil

    d = tmp_path / "k"
    shutil.copytree(keys, d)
    from cryptography.hazmat.primitives import serialization

    (d / "s2.ed25519").write_bytes(Ed25519PrivateKey.generate().private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption()))
    with pytest.raises(SecurityError, match="does not match s2's key"):
        Security.load(d, "s2", NET, PEERS).signer()
    data = json.loads((d / "members.json").read_text())
    del data["ed25519"]["s3"]
    (d / "members.json").write_text(json.dumps(data))
    with pytest.raises(SecurityError, match="no signing key for s3"):
        Security.load(d, "s1", NET, PEERS).verifier()


def test_owner_of_each_key():
    assert owner(K.estimate("s2")) == owner(K.tracks("s2")) == "s2"
    assert owner(K.scan("s1")) == owner(K.truth()) == owner(K.ctl()) == "world"
    assert owner(K.alive("s1")) is None and owner("sensornet/x") is None


def test_sealed_messages_open_and_decode_the_same(signers, verifier):
    payload = _estimate()
    sealed = signers["s2"].seal(K.estimate("s2"), payload)
    assert len(sealed) == len(payload) + TRAILER and sealed.startswith(payload)
    body, why = verifier.open(K.estimate("s2"), sealed)
    assert why is None and body == payload
    assert decode(body).mixture.weights.tolist() == [0.9]
    assert inner(sealed) == payload and inner(payload) == payload
    for key, data in [(K.scan("s1"), encode(Scan("s1", 3, np.zeros((2, 2)), seq=3))),
                      (K.ctl(), encode(Control("end", "r"))), (K.truth(), b"any bytes")]:
        body, why = verifier.open(key, signers["world"].seal(key, data))
        assert (body, why) == (data, None)


def test_replayed_and_reordered_copies_are_refused(signers, verifier):
    key = K.estimate("s2")
    first = signers["s2"].seal(key, _estimate(k=3))
    second = signers["s2"].seal(key, _estimate(k=3, rnd=1))
    assert verifier.open(key, first)[1] is None
    assert verifier.open(key, first) == (None, "replayed")  # the same bytes again
    assert verifier.open(key, second)[1] is None
    assert verifier.open(key, first) == (None, "replayed")  # older than one already taken
    # stamps are per key: the world's ctl is not ordered against its scans
    ctl = signers["world"].seal(K.ctl(), b"c")
    scan = signers["world"].seal(K.scan("s1"), b"s")
    assert verifier.open(K.scan("s1"), scan)[1] is None
    assert verifier.open(K.ctl(), ctl)[1] is None
    # a restarted sender (a new signer, same key) is newer than anything before
    later = Signer(signers["s2"]._key).seal(key, _estimate(k=4))
    assert verifier.open(key, later)[1] is None


def test_forged_moved_tampered_or_unsigned_messages_are_unauthenticated(keys, signers,
                                                                         verifier):
    key = K.estimate("s2")
    payload = _estimate()
    cases = {
        "s3's key on s2's estimate": signers["s3"].seal(key, payload),
        "a key outside the roster": Signer(Ed25519PrivateKey.generate()).seal(key, payload),
        "unsigned": payload,
        "truncated": signers["s2"].seal(key, payload)[:-1],
        "s2's own, put on s3's key": None,
        "a payload byte changed": None,
        "the stamp changed": None,
        "signed for another network": signers["s2"].seal(Keys("other").estimate("s2"),
                                                          payload),
        "a peer's ctl": signers["s1"].seal(K.ctl(), encode(Control("end", "x"))),
    }
    good = signers["s2"].seal(key, payload)
    b = bytearray(good)
    b[40] ^= 1
    cases["a payload byte changed"] = bytes(b)
    b = bytearray(good)
    b[len(payload) + 7] ^= 1
    cases["the stamp changed"] = bytes(b)
    for what, data in cases.items():
        target = K.ctl() if what == "a peer's ctl" else key
        if what == "s2's own, put on s3's key":
            data, target = good, K.estimate("s3")
        assert verifier.open(target, data) == (None, "unauthenticated"), what
    # none of these moved the replay bookkeeping: the genuine message still opens
    assert verifier.open(key, good)[1] is None


def test_without_the_signature_check_the_trailer_and_replays_are_still_checked(signers,
                                                                                 keys):
    """``check_signature=False`` (a link that proves the sender): a wrong signature is not
    looked at, but an unsigned message is still refused and a copy is still ``replayed``."""
    v = Security.load(keys, "s1", NET, PEERS).verifier()
    key = K.estimate("s2")
    payload = _estimate(k=5)
    forged = signers["s3"].seal(key, payload)  # a link would have refused its sender
    assert v.open(key, forged) == (None, "unauthenticated")
    assert v.open(key, forged, check_signature=False) == (payload, None)
    assert v.open(key, forged, check_signature=False) == (None, "replayed")
    assert v.open(key, payload, check_signature=False) == (None, "unauthenticated")
    assert v.open(K.estimate("s9"), signers["s2"].seal(K.estimate("s9"), payload),
                  check_signature=False) == (None, "unauthenticated")  # owner not in roster


def test_signatures_are_checked_where_a_link_does_not_prove_the_sender(keys, tmp_path):
    """A peer checks every signature when the network has a router (which the access control
    lets put on every key), runs with recovery (a publisher's cache replies on any member's
    ingress) or with a user's Zenoh config file; in a mesh of mutual-TLS links without any of
    these, the access control already refuses every put but the key owner's, and only the
    trailer and the replay check run."""
    routed = tmp_path / "routed"
    make_keys(NET, ["world", *PEERS, "router"], routed)
    for folder, recover, conf, expect in ((keys, False, None, False), (keys, True, None, True),
                                          (routed, False, None, True),
                                          (keys, False, "zenoh.json5", True)):
        t = Transport(K, "s1", "s1", ("s2", "s3"), None, ((), (), conf, None, True),
                      security=Security.load(folder, "s1", NET, PEERS), recover=recover)
        t.arm_signatures()  # what open() does first, before any session
        assert t.verifier is not None and t.check_signatures is expect, (folder, recover, conf)


class _Sample:
    def __init__(self, key: str, payload: bytes) -> None:
        self.key_expr, self._p = key, payload

    @property
    def payload(self):
        return self

    def to_bytes(self) -> bytes:
        return self._p


def test_a_peer_counts_what_it_refused_and_fuses_what_it_took(keys, signers):
    """The transport callback of s1 (no session): a genuine signed estimate of s2 goes on the
    queue without its trailer; a replayed copy and one signed with s3's key are counted under
    ``replayed`` / ``unauthenticated`` in the core's rejection counters and never queued."""
    scn = load_scenario("seed000")
    core = make_peer(scn, "s1", 0, network=NET)
    c = core.consensus
    t = Transport(core.keys, "s1", "s1", c.o.neighbours, core.admission, ((), (), None, None,
                                                                             True))
    t.verifier = Security.load(keys, "s1", NET, PEERS).verifier()
    key = K.estimate("s2")
    genuine = signers["s2"].seal(key, _estimate(k=1))
    t._on_sample(_Sample(key, genuine))
    t._on_sample(_Sample(key, genuine))  # replayed
    t._on_sample(_Sample(key, signers["s3"].seal(key, _estimate(k=1, rnd=0))))
    t._on_sample(_Sample(key, _estimate(k=1)))  # unsigned
    queued = []
    while not t.q.empty():
        queued.append(t.q.get())
    assert queued == [("msg", key, _estimate(k=1))]
    snap = core.snapshot()
    assert snap["rejected"] == {"replayed": 1, "unauthenticated": 2}
    assert snap["rejected_before_decoding"] == 3
    # what was queued is a plain message the core decodes
    core.receive(key, queued[0][2], 0.0, admitted=True)
    assert core.snapshot()["rejected"] == {"replayed": 1, "unauthenticated": 2}
    assert core.received["estimate"] == 1


def test_signer_stamps_increase_even_within_one_clock_tick(signers, monkeypatch):
    monkeypatch.setattr(envelope.time, "time_ns", lambda: 1000)
    s = Signer(Ed25519PrivateKey.generate())
    stamps = [int.from_bytes(s.stamp(), "big") for _ in range(5)]
    assert stamps == [1000, 1001, 1002, 1003, 1004]


def test_world_messages_need_the_worlds_key(keys, signers, verifier):
    """Only the world signs scans and control: a member's signature on a scan is refused."""
    data = encode(Scan("s1", 5, np.ones((1, 2)), seq=5))
    assert verifier.open(K.scan("s1"), signers["s2"].seal(K.scan("s1"), data))[1] == \
        "unauthenticated"
    assert verifier.open(K.scan("s1"), signers["world"].seal(K.scan("s1"), data))[1] is None


def test_signing_benchmark_runs(capsys):
    """benchmarks/bench_signing.py prints one row per message kind and the per-scan cost."""
    from benchmarks import bench_signing

    assert bench_signing.main(["--n", "3"]) == 0
    out = capsys.readouterr().out
    rows = [ln for ln in out.splitlines() if ln.startswith("| ") and "---" not in ln]
    assert [r.split("|")[1].strip() for r in rows[1:7]] == [
        "scan (8 measurements)", "truth (4 targets)", "estimate (1 component)",
        "estimate (10 components)", "estimate (100 components)", "tracks (4 targets)"]
    assert all("(+76)" in r for r in rows[1:7])  # the trailer: stamp, signature, tag
    assert "| total |" in out


class _Clock:
    """A wall clock in nanoseconds that a test sets."""

    def __init__(self, t: float) -> None:
        self.ns = int(t * 1e9)

    def __call__(self) -> int:
        return self.ns

    def set(self, t: float) -> None:
        self.ns = int(t * 1e9)


HOUR = 3600.0


def test_a_sender_whose_clock_ran_an_hour_ahead_is_taken_again_once_corrected(keys):
    """Before: every honest message after the correction was ``replayed`` for an hour."""
    sender_clock, receiver_clock = _Clock(1000.0 + HOUR), _Clock(1000.0)
    sign_key = Security.load(keys, "s2", NET, PEERS).signer()._key
    signer = Signer(sign_key, clock=sender_clock)
    verifier = Security.load(keys, "s1", NET, PEERS).verifier()
    verifier._clock = receiver_clock
    key = K.estimate("s2")
    # while its clock is an hour ahead, its messages are refused as such and set no bar
    assert verifier.open(key, signer.seal(key, _estimate(k=1))) == (None, "ahead")
    sender_clock.set(1001.0)  # corrected
    receiver_clock.set(1001.0)
    sealed = signer.seal(key, _estimate(k=2))
    assert verifier.open(key, sealed) == (_estimate(k=2), None)  # taken at once
    assert verifier.open(key, sealed) == (None, "replayed")  # and a copy still refused
    sender_clock.set(1001.5)
    receiver_clock.set(1001.5)
    assert verifier.open(key, signer.seal(key, _estimate(k=3)))[1] is None


def test_a_skew_within_max_ahead_is_taken_and_stamps_still_increase(keys):
    sender_clock, receiver_clock = _Clock(1005.0), _Clock(1000.0)  # 5 s ahead: tolerated
    signer = Signer(Security.load(keys, "s2", NET, PEERS).signer()._key, clock=sender_clock)
    verifier = Security.load(keys, "s1", NET, PEERS).verifier()
    verifier._clock = receiver_clock
    key = K.estimate("s2")
    assert verifier.open(key, signer.seal(key, _estimate(k=1)))[1] is None
    sender_clock.set(1000.0)  # corrected by 5 s (< MAX_AHEAD): stamps go on increasing
    stamps = [int.from_bytes(signer.stamp(), "big") for _ in range(3)]
    assert stamps == sorted(stamps) and stamps[0] > int(1000.0 * 1e9)
    assert verifier.open(key, signer.seal(key, _estimate(k=2)))[1] is None


def test_a_receiver_whose_clock_stepped_back_recovers_within_max_ahead(keys):
    """Both clocks an hour ahead, then both corrected: the receiver's bar (an hour ahead) is
    lowered to its clock - MAX_AHEAD, so honest messages are taken again at once."""
    clock = _Clock(1000.0 + HOUR)
    signer = Signer(Security.load(keys, "s2", NET, PEERS).signer()._key, clock=clock)
    verifier = Security.load(keys, "s1", NET, PEERS).verifier()
    verifier._clock = clock
    key = K.estimate("s2")
    assert verifier.open(key, signer.seal(key, _estimate(k=1)))[1] is None
    old = signer.seal(key, _estimate(k=1))  # stamped an hour ahead, captured
    clock.set(1000.0)
    sealed = signer.seal(key, _estimate(k=2))
    assert verifier.open(key, sealed)[1] is None  # at once, not in an hour
    assert verifier.open(key, sealed)[1] == "replayed"
    assert verifier.open(key, old)[1] == "ahead"  # nor does the hour-ahead copy come back
