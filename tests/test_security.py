"""Member keys (sensornet keys), mutual TLS and the network's access control, in one process.

The Zenoh sessions here are real (loopback, free ports); the whole-run attacks against peer
processes in secure mode are in tests/test_attacks_secure.py.
"""

from __future__ import annotations

import json
import threading
import time

import pytest
import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID
from sensornet.peers.security import (
    Security,
    SecurityError,
    acl_rules,
    common_name,
    keys_network,
    make_keys,
    tls_endpoint,
)
from sensornet.peers.session import SessionError, free_port, open_session, zenoh_config
from sensornet.protocol.keys import Keys

from sensornet.cli import main

PEERS = ("s1", "s2", "s3")
MEMBERS = ["world", *PEERS]


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    d = tmp_path_factory.mktemp("keys")
    make_keys("net1", MEMBERS, d)
    return d


@pytest.fixture(scope="module")
def other_ca(tmp_path_factory):
    d = tmp_path_factory.mktemp("other")
    make_keys("net1", MEMBERS, d)  # same names, another CA
    return d


def _cert(path):
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_keys_are_a_ca_and_one_certificate_per_member(keys):
    ca = _cert(keys / "ca.pem")
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for m in MEMBERS:
        cert = _cert(keys / f"{m}.pem")
        assert common_name(keys / f"{m}.pem") == m
        assert cert.issuer == ca.subject
        cert.verify_directly_issued_by(ca)  # raises if the signature is not the CA's
        eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert set(eku) == {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH}
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert "localhost" in san.get_values_for_type(x509.DNSName)
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        key = (keys / f"{m}.key").read_bytes()
        assert key.startswith(b"-----BEGIN PRIVATE KEY-----")
        assert (keys / f"{m}.key").stat().st_mode & 0o077 == 0  # private: owner only
    assert keys_network(keys) == "net1"
    assert json.loads((keys / "members.json").read_text())["members"] == MEMBERS


def test_keys_reuse_the_ca_add_members_and_rotate(tmp_path):
    make_keys("net2", ["world", "s1"], tmp_path)
    ca, s1 = (tmp_path / "ca.pem").read_bytes(), (tmp_path / "s1.pem").read_bytes()
    make_keys("net2", ["s4"], tmp_path)  # a member added later: same CA, s1 untouched
    assert (tmp_path / "ca.pem").read_bytes() == ca
    assert (tmp_path / "s1.pem").read_bytes() == s1
    _cert(tmp_path / "s4.pem").verify_directly_issued_by(_cert(tmp_path / "ca.pem"))
    make_keys("net2", ["s1"], tmp_path, overwrite=True)  # rotation: a new key for s1
    assert (tmp_path / "s1.pem").read_bytes() != s1
    assert json.loads((tmp_path / "members.json").read_text())["members"] == [
        "world", "s1", "s4"]
    with pytest.raises(SecurityError, match="another network"):
        make_keys("net3", ["s1"], tmp_path)
    with pytest.raises(ValueError):
        make_keys("net2", ["bad/name"], tmp_path)


def test_keys_command(tmp_path, capsys):
    assert main(["keys", "netc", "--out", str(tmp_path / "a")]) == 0
    assert {p.name for p in (tmp_path / "a").glob("*.pem")} == {
        "ca.pem", "world.pem", "s1.pem", "s2.pem", "s3.pem", "view.pem"}  # view: read-only
    assert main(["keys", "netc", "--out", str(tmp_path / "b"), "--members", "world,x,y",
                 "--hosts", "localhost,127.0.0.1,10.0.0.7,node1"]) == 0
    san = _cert(tmp_path / "b" / "x.pem").extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value
    assert "node1" in san.get_values_for_type(x509.DNSName)
    assert main(["keys", "other", "--out", str(tmp_path / "b")]) == 2
    assert "another network" in capsys.readouterr().err


def test_security_load_refuses_incomplete_or_foreign_folders(keys, tmp_path):
    Security.load(keys, "s1", "net1", PEERS)
    with pytest.raises(SecurityError, match="missing s9.pem"):
        Security.load(keys, "s9", "net1", PEERS)
    with pytest.raises(SecurityError, match="keys of network 'net1'"):
        Security.load(keys, "s1", "net2", PEERS)
    with pytest.raises(SecurityError, match="no ca.pem"):
        keys_network(tmp_path)
    sec = Security.load(keys, "s1", "net1", PEERS)
    with pytest.raises(SessionError, match="tls/ endpoints"):
        zenoh_config(listen=["tcp/127.0.0.1:7447"], security=sec)


def test_acl_lets_each_member_put_only_its_own_keys():
    acl = acl_rules("net1", PEERS)
    k = Keys("net1")
    assert acl["enabled"] and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    pol = {p["subjects"][0]: p["rules"] for p in acl["policies"]}
    subj = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert subj["m-s2"] == ["s2"] and subj["m-world"] == ["world"]

    def puts(member):
        return {e for r in pol[f"m-{member}"] for e in rules[r]["key_exprs"]
                if "put" in rules[r]["messages"] and "ingress" in rules[r]["flows"]}

    # and the recovery machinery's heartbeats under its own keys (--recover, routed runs)
    assert puts("s2") == {k.estimate("s2"), k.tracks("s2"), k.telemetry("s2"),
                          f"{k.estimate('s2')}/@adv/**"}
    assert puts("world") == {k.scan("*"), k.truth(), k.ctl(), f"{k.scan('*')}/@adv/**"}

    def allowed(member, message):
        return {e for r in pol[f"m-{member}"] for e in rules[r]["key_exprs"]
                if message in rules[r]["messages"] and "ingress" in rules[r]["flows"]}

    # a cache answers queries only under its owner's keys; a peer asks where it listens
    assert allowed("s2", "declare_queryable") == {f"{k.estimate('s2')}/@adv/**"}
    assert allowed("world", "declare_queryable") == {f"{k.scan('*')}/@adv/**"}
    assert allowed("s3", "query") == {f"{k.scan('s3')}/@adv/**", f"{k.estimate('*')}/@adv/**"}
    tokens = {e for r in pol["m-s3"] for e in rules[r]["key_exprs"]
              if "liveliness_token" in rules[r]["messages"] and "ingress" in rules[r]["flows"]}
    assert tokens == {k.alive("s3"), k.ready("s3")}


# -- real sessions ----------------------------------------------------------------------------
def _attempt(conf: zenoh.Config, ep: str) -> str | None:
    """Connect once (1 s); the authenticated name of the other side, or None if refused."""
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([ep]))
    conf.insert_json5("connect/timeout_ms", "1000")
    conf.insert_json5("connect/exit_on_failure", "true")
    try:
        s = zenoh.open(conf)
    except Exception:
        return None
    try:
        return next((lk.auth_identifier for lk in s.info.links()), "")
    finally:
        s.close()


@pytest.mark.network
def test_mutual_tls_refuses_no_certificate_another_ca_and_plain_tcp(keys, other_ca):
    port = free_port()
    s1 = open_session([tls_endpoint(port)], security=Security.load(keys, "s1", "net1", PEERS))
    try:
        ep = tls_endpoint(port)
        no_cert = zenoh.Config()  # trusts the CA, but shows no certificate of its own
        no_cert.insert_json5("transport/link/tls/root_ca_certificate",
                             json.dumps(str(keys / "ca.pem")))
        assert _attempt(no_cert, ep) is None
        foreign = zenoh.Config()  # a "s2" certificate from another CA
        Security.load(other_ca, "s2", "net1", PEERS).apply(foreign)
        assert _attempt(foreign, ep) is None
        assert _attempt(zenoh.Config(), f"tcp/127.0.0.1:{port}") is None
        member = zenoh.Config()
        Security.load(keys, "s2", "net1", PEERS).apply(member)
        assert _attempt(member, ep) == "s1"  # a member connects and sees who it talks to
    finally:
        s1.close()


def _stranger_keys(keys, tmp_path):
    """A certificate of the right CA for a name that is not in the roster."""
    import shutil

    d = tmp_path / "stranger"
    d.mkdir()
    for f in ("ca.pem", "ca.key"):
        shutil.copy(keys / f, d / f)
    make_keys("net1", ["s9"], d)
    return d


@pytest.mark.network
def test_access_control_refuses_what_a_member_may_not_put(keys, tmp_path):
    """s3 (a member with a valid key) and s9 (a valid certificate, no rights) try every
    key they do not own; s1 and the world receive only what their owners may send."""
    k = Keys("net1")
    p1, p3 = free_port(), free_port()
    stranger = _stranger_keys(keys, tmp_path)

    def sec(member, folder=keys):
        return Security.load(folder, member, "net1", PEERS)

    s1 = open_session([tls_endpoint(p1)], security=sec("s1"))
    s3 = open_session([tls_endpoint(p3)], [tls_endpoint(p1)], security=sec("s3"))
    world = open_session([], [tls_endpoint(p1), tls_endpoint(p3)], security=sec("world"))
    s9 = open_session([], [tls_endpoint(p1), tls_endpoint(p3)], security=sec("s9", stranger))
    got, live, ready = [], [], []
    lock = threading.Lock()
    done, probe = threading.Event(), threading.Event()

    def on(sample):
        if sample.payload.to_bytes() == b"probe":
            probe.set()
            return
        with lock:
            got.append((str(sample.key_expr), sample.payload.to_bytes()))
            if sample.payload.to_bytes() == b"last":
                done.set()

    try:
        subs = [s1.declare_subscriber(x, on) for x in (k.scan("s1"), k.truth(), k.ctl(),
                                                       k.estimate("*"))]
        subs.append(s1.liveliness().declare_subscriber(
            k.alive("*"), lambda s: live.append(str(s.key_expr)), history=True))
        subs.append(world.liveliness().declare_subscriber(
            k.ready("*"), lambda s: ready.append(str(s.key_expr)), history=True))
        end = time.monotonic() + 5  # both attackers linked to s1 and the world (which do
        while time.monotonic() < end and not (  # not listen: world and s9 are not linked)
                len(list(s1.info.peers_zid())) >= 3 and len(list(world.info.peers_zid())) >= 2):
            time.sleep(0.02)
        end = time.monotonic() + 5
        while not probe.is_set() and time.monotonic() < end:  # s1's subscriptions are up
            s3.put(k.estimate("s3"), b"probe")
            probe.wait(0.05)
        assert probe.is_set()
        tokens = []
        for who in (s3, s9):
            for key in (k.estimate("s2"), k.scan("s1"), k.ctl(), k.truth()):
                who.put(key, b"spoofed")
            tokens += [who.liveliness().declare_token(k.alive("s1")),
                       who.liveliness().declare_token(k.ready("s2"))]
        tokens.append(s3.liveliness().declare_token(k.alive("s3")))
        tokens.append(s3.liveliness().declare_token(k.ready("s3")))
        s3.put(k.estimate("s3"), b"own")
        world.put(k.scan("s1"), b"world")
        world.put(k.ctl(), b"last")
        assert done.wait(5), got
        time.sleep(0.3)  # anything refused would have arrived by now (another session's)
        assert sorted(got) == sorted([(k.estimate("s3"), b"own"), (k.scan("s1"), b"world"),
                                      (k.ctl(), b"last")])
        assert live == [k.alive("s3")]
        assert ready == [k.ready("s3")]
        replies = [str(r.ok.key_expr) for r in s1.liveliness().get(k.alive("*"), timeout=1)
                   if r.ok is not None]
        assert replies == [k.alive("s3")]
        for t in tokens:
            t.undeclare()
        for s in subs:
            s.undeclare()
    finally:
        for s in (s9, world, s3, s1):
            s.close()


def test_secure_flags_are_refused_in_one_line(keys, tmp_path, capsys):
    def refused(argv, *needles):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        for n in needles:
            assert n in err[0], err[0]

    refused(["run", "seed000", "--sim", "--secure"], "--secure needs real processes")
    refused(["run", "seed000", "--secure", str(keys), "--network", "other",
             "--out", str(tmp_path / "r1")], "keys of network 'net1'")
    refused(["run", "seed000", "--secure", str(keys), "--listen", "tcp/127.0.0.1:7447",
             "--out", str(tmp_path / "r2")], "tls/ endpoints")
    refused(["peer", "s1", "--network", "net2", "--secure", str(keys)],
            "keys of network 'net1'")
    refused(["world", "seed000", "--network", "net1", "--secure", str(keys),
             "--listen", "tcp/127.0.0.1:7447"], "tls/ endpoints")
    partial = tmp_path / "partial"
    make_keys("net1", ["world", "s1"], partial)
    refused(["run", "seed000", "--secure", str(partial), "--out", str(tmp_path / "r4")],
            "no key for s2, s3")
    assert not any((tmp_path / f"r{i}").exists() for i in (1, 2, 4))  # nothing left behind


@pytest.mark.network
def test_a_scenario_security_table_runs_secure(keys, tmp_path):
    """``[security] keys = "DIR"`` (relative to the scenario file) is ``--secure DIR``."""
    from sensornet.sim.scenario import ScenarioError, load_scenario, scenario_text

    folder = tmp_path / "scn"
    folder.mkdir()
    import shutil

    shutil.copytree(keys, folder / "keys")
    text = scenario_text("seed000") + '\n[security]\nkeys = "keys"\n'
    (folder / "secure.toml").write_text(text)
    scn = load_scenario(folder / "secure.toml")
    assert scn.security == str(folder / "keys")
    with pytest.raises(ScenarioError, match="did you mean 'security.keys'"):
        load_scenario("seed000", overrides={"security.key": "x"})
    # the launcher's peers and world get --secure: a wrong network name is refused at once
    assert main(["run", str(folder / "secure.toml"), "--network", "other",
                 "--out", str(tmp_path / "r")]) == 2
    out = tmp_path / "run"
    assert main(["run", str(folder / "secure.toml"), "--no-rerun", "--out", str(out),
                 "--set", "scenario.num_scans=15", "--set", "birth.model=truth"]) == 0
    cmds = json.loads((out / "commands.json").read_text())
    assert all("--secure" in c for c in cmds.values())
    assert all(e.startswith("tls/") for c in cmds.values()
               for i, e in enumerate(c) if i and c[i - 1] in ("--listen", "--connect"))
