"""Who may speak on a network: member keys and certificates, mutual TLS, per-key access control.

``sensornet keys NETWORK --out DIR`` (:func:`make_keys`) writes a network CA and, per member
(every peer and the world), a private key and a certificate whose common name is the member's
name, all plain PEM files (``openssl x509 -in DIR/s1.pem -noout -text`` reads them):

    DIR/ca.pem  DIR/ca.key          the network's CA (keep ca.key off the members' machines)
    DIR/<name>.pem  DIR/<name>.key  one per member: CN=<name>, O=<network>, signed by the CA
    DIR/<name>.ed25519              one per member: its message-signing key (Ed25519)
    DIR/members.json                the roster: member names and signing public keys

A member process in secure mode (``--secure DIR``, :class:`Security`) builds its Zenoh session
with ``tls/`` endpoints, mutual TLS against the network's CA only, and the network's access
control policy (:func:`acl_config`, default deny, subjects by certificate common name): a peer
may put only on its own ``estimate/`` and ``tracks/`` keys and declare only its own ``alive/``
and ``ready/`` liveliness tokens; only the world may put ``scan/``, ``truth`` and ``ctl``.
Zenoh applies the policy where a message *arrives* (each member filters what it receives), so
every member loads the same policy: a member that lies about whose key it puts on is refused
by every other member, whatever its own process does. On top of that every message is signed by
its sender's Ed25519 key and checked by each receiver against the roster, with replays refused
(:mod:`protocol.envelope`): what a router relays or a recording holds still names its sender.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
import re
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from peers.session import SessionError
from protocol.keys import Keys, check_name

WORLD = "world"
"""The member name of the world process (scans, truth, control)."""
CA_CERT, CA_KEY = "ca.pem", "ca.key"
SIGN_KEY = ".ed25519"
"""Suffix of a member's message-signing private key (``NAME.ed25519``, PEM PKCS#8)."""
SIGNING = "ed25519"
"""Field of ``members.json`` holding the roster: member name -> signing public key."""
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
"""Names every member certificate is valid for (the host part of the endpoints dialled)."""


class SecurityError(SessionError):
    """Keys could not be made or a secure-mode folder is incomplete (one line)."""


# -- keys and certificates --------------------------------------------------------------------
def _name(cn: str, org: str | None = None):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    attrs = [x509.NameAttribute(NameOID.COMMON_NAME, cn)]
    if org:
        attrs.append(x509.NameAttribute(NameOID.ORGANIZATION_NAME, org))
    return x509.Name(attrs)


def _write(path: Path, data: bytes, private: bool = False) -> None:
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if private else 0o644)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    tmp.replace(path)


def _san(hosts: Iterable[str]):
    from cryptography import x509

    names = []
    for h in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return x509.SubjectAlternativeName(names)


def make_keys(network: str, members: Sequence[str], out: Path, days: int = 365,
              hosts: Sequence[str] = DEFAULT_HOSTS, overwrite: bool = False) -> list[Path]:
    """Write a network CA and a key + certificate per member into ``out``; returns the paths.

    An existing CA in ``out`` is reused (so members can be added later with the same CA);
    an existing member key is kept unless ``overwrite`` (key rotation: issue a new one).
    Keys are ECDSA P-256 (what every TLS stack accepts); member certificates carry both
    serverAuth and clientAuth (a peer listens and connects) and ``hosts`` as SANs. Each
    member also gets a message-signing key ``NAME.ed25519`` (made where missing, new with
    ``overwrite``), whose public half goes into the roster, ``members.json``.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
    from cryptography.x509.oid import ExtendedKeyUsageOID

    check_name(network, "network name")
    members = list(dict.fromkeys(members))
    if not members:
        raise SecurityError("no members: give --members a,b,c or --scenario")
    for m in members:
        check_name(m, "member name")
    if CA_CERT.removesuffix(".pem") in members:
        raise SecurityError("'ca' cannot be a member name (it is the CA's file)")
    out.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=days)
    pem = serialization.Encoding.PEM
    no_pw = serialization.NoEncryption()
    pkcs8 = serialization.PrivateFormat.PKCS8

    ca_cert_path, ca_key_path = out / CA_CERT, out / CA_KEY
    if ca_cert_path.exists() and ca_key_path.exists():
        ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), None)
        ca_cert = x509.load_pem_x509_certificate(ca_cert_path.read_bytes())
        org = ca_cert.subject.get_attributes_for_oid(x509.oid.NameOID.ORGANIZATION_NAME)
        if not org or org[0].value != network:
            raise SecurityError(f"{out} holds the CA of another network "
                                f"({org[0].value if org else '?'!r}); use another folder")
    else:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        subject = _name(f"sensornet {network} CA", network)
        ca_cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
                   .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(start).not_valid_after(end)
                   .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                   .add_extension(x509.KeyUsage(
                       digital_signature=False, content_commitment=False,
                       key_encipherment=False, data_encipherment=False, key_agreement=False,
                       key_cert_sign=True, crl_sign=True, encipher_only=False,
                       decipher_only=False), critical=True)
                   .add_extension(x509.SubjectKeyIdentifier.from_public_key(
                       ca_key.public_key()), critical=False)
                   .sign(ca_key, hashes.SHA256()))
        _write(ca_key_path, ca_key.private_bytes(pem, pkcs8, no_pw), private=True)
        _write(ca_cert_path, ca_cert.public_bytes(pem))
    written = [ca_cert_path, ca_key_path]
    for m in members:
        key_path, cert_path = out / f"{m}.key", out / f"{m}.pem"
        if key_path.exists() and cert_path.exists() and not overwrite:
            written += [cert_path, key_path]
            continue
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (x509.CertificateBuilder().subject_name(_name(m, network))
                .issuer_name(ca_cert.subject).public_key(key.public_key())
                .serial_number(x509.random_serial_number())
                .not_valid_before(start).not_valid_after(end)
                .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                .add_extension(x509.KeyUsage(
                    digital_signature=True, content_commitment=False, key_encipherment=False,
                    data_encipherment=False, key_agreement=False, key_cert_sign=False,
                    crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
                .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                      ExtendedKeyUsageOID.CLIENT_AUTH]),
                               critical=False)
                .add_extension(_san(hosts), critical=False)
                .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                    ca_key.public_key()), critical=False)
                .sign(ca_key, hashes.SHA256()))
        _write(key_path, key.private_bytes(pem, pkcs8, no_pw), private=True)
        _write(cert_path, cert.public_bytes(pem))
        written += [cert_path, key_path]
    roster = out / "members.json"
    known = json.loads(roster.read_text()) if roster.exists() else {}
    signing = dict(known.get(SIGNING, {}))
    for m in members:  # message signing keys (Ed25519): made where missing, or rotated
        sign_path = out / f"{m}{SIGN_KEY}"
        if overwrite or not sign_path.is_file():
            _write(sign_path, Ed25519PrivateKey.generate().private_bytes(pem, pkcs8, no_pw),
                   private=True)
        signing[m] = _public_b64(serialization.load_pem_private_key(
            sign_path.read_bytes(), None).public_key())
        written.append(sign_path)
    _write(roster, json.dumps({"network": network,
                               "members": list(dict.fromkeys([*known.get("members", []),
                                                              *members])),
                               SIGNING: signing}, indent=1).encode())
    return [*written, roster]


def _public_b64(public_key) -> str:
    """An Ed25519 public key as the base64 of its DER SubjectPublicKeyInfo: the one line
    between the PEM markers of ``openssl pkey -in NAME.ed25519 -pubout``."""
    import base64

    from cryptography.hazmat.primitives import serialization

    der = public_key.public_bytes(serialization.Encoding.DER,
                                  serialization.PublicFormat.SubjectPublicKeyInfo)
    return base64.b64encode(der).decode()


def load_roster(folder: str | Path) -> dict:
    """The members' message-signing public keys from ``members.json`` (name -> key)."""
    import base64

    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import load_der_public_key

    path = Path(folder) / "members.json"
    try:
        entries = json.loads(path.read_text()).get(SIGNING, {}) if path.is_file() else {}
        roster = {n: load_der_public_key(base64.b64decode(v)) for n, v in entries.items()}
    except (ValueError, TypeError, AttributeError) as exc:
        raise SecurityError(f"{path}: unreadable signing roster ({exc})") from None
    bad = [n for n, k in roster.items() if not isinstance(k, Ed25519PublicKey)]
    if bad:
        raise SecurityError(f"{path}: the signing keys of {', '.join(bad)} are not Ed25519")
    return roster


def keys_network(folder: str | Path) -> str:
    """The network a keys folder was made for (its CA's organisation name)."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    path = Path(folder) / CA_CERT
    if not path.is_file():
        raise SecurityError(f"{folder}: no {CA_CERT} (make the keys with: sensornet keys "
                            f"NETWORK --out {folder})")
    org = x509.load_pem_x509_certificate(path.read_bytes()).subject \
        .get_attributes_for_oid(NameOID.ORGANIZATION_NAME)
    if not org:
        raise SecurityError(f"{path} names no network (its O= field is empty)")
    return str(org[0].value)


def common_name(cert_path: Path) -> str:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    cert = x509.load_pem_x509_certificate(Path(cert_path).read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)


# -- access control ---------------------------------------------------------------------------
ROUTER_PREFIX = "router"
"""Members whose name starts with this are routers (``sensornet router``): they relay."""


def acl_rules(network: str, peers: Sequence[str], world: str = WORLD,
              routers: Sequence[str] = ()) -> dict:
    """The network's Zenoh ``access_control`` section (default deny).

    Zenoh checks a put or a declaration where it arrives (ingress, against the sender's
    certificate name) and where it leaves (egress, against the *receiver's*): every member
    loads this same policy, so each refuses what another member may not send, whatever that
    member's own process does. Subjects are certificate common names (reliable in peer mode;
    user names are not). Per member:

    - peer ``p``: puts ``estimate/p`` and ``tracks/p``; liveliness tokens ``alive/p`` and
      ``ready/p``; subscribes to its own ``scan/p``, ``truth``, ``ctl`` and ``estimate/*``
      (what it fuses), to liveliness ``alive/*``;
    - the world: puts ``scan/*``, ``truth``, ``ctl``; token ``alive/<world>``; liveliness
      subscriptions on ``alive/*`` and ``ready/*``; subscribes to ``scan/*`` (its own tools);
    - recovery (``--recover``, Zenoh's advanced publisher/subscriber, routed runs): a
      publisher of ``K`` also puts heartbeats on ``K/@adv/**`` and answers queries there from
      its cache; a subscriber subscribes and queries there. The same owners as ``K``: peer
      ``p`` on ``estimate/p/@adv/**``, the world on ``scan/*/@adv/**``; peer ``p`` asks on
      ``scan/p/@adv/**`` and ``estimate/*/@adv/**``;
    - a router (``routers``): relays anything on the network's keys. A member behind a router
      sees every message as coming from the router's certificate, so the router is where the
      per-member rules are enforced (at its ingress, by the client's certificate name).
    """
    k = Keys(network)
    everything = f"{k.base}/**"
    # ``**`` does not match a chunk that starts with "@": the advanced pub/sub keys, spelled out
    recovery = f"{k.base}/*/*/@adv/**"

    def adv(key: str) -> str:
        return f"{key}/@adv/**"

    def rule(rid: str, messages: list[str], key_exprs: list[str],
             flows: tuple[str, ...] = ("ingress",)) -> dict:
        return {"id": rid, "permission": "allow", "flows": list(flows), "messages": messages,
                "key_exprs": key_exprs}

    rules = [
        rule(f"{world}-put", ["put"], [k.scan("*"), k.truth(), k.ctl()]),
        rule(f"{world}-token", ["liveliness_token"], [k.alive(world)]),
        rule(f"{world}-hear", ["declare_liveliness_subscriber", "liveliness_query"],
             [k.alive("*"), k.ready("*")]),
        # the world's own tools (the launcher's process-fault injector) follow the scans
        rule(f"{world}-watch", ["declare_subscriber"], [k.scan("*")]),
        # recovering scan publishers: heartbeats, and a cache that answers queries
        rule(f"{world}-recover", ["put", "declare_queryable"], [adv(k.scan("*"))]),
        # liveliness replies (who is alive) and replies from a publisher's cache, on every
        # member's ingress (a reply answers a query its receiver made)
        rule("replies", ["reply"], [everything, recovery]),
        # egress is checked against the receiving member: a member sends what it may send
        # (every receiver checks the sender on its ingress)
        rule("send", ["put", "delete", "liveliness_token", "declare_subscriber",
                      "declare_liveliness_subscriber", "liveliness_query", "reply", "query",
                      "declare_queryable"],
             [everything, recovery], flows=("egress",)),
    ]
    subjects = [{"id": f"m-{world}", "cert_common_names": [world]}]
    policies = [{"rules": [f"{world}-put", f"{world}-token", f"{world}-hear",
                           f"{world}-watch", f"{world}-recover", "replies", "send"],
                 "subjects": [f"m-{world}"]}]
    for p in peers:
        check_name(p, "peer name")
        rules += [
            rule(f"{p}-put", ["put"], [k.estimate(p), k.tracks(p)]),
            rule(f"{p}-token", ["liveliness_token"], [k.alive(p), k.ready(p)]),
            rule(f"{p}-hear", ["declare_subscriber"],
                 [k.scan(p), k.truth(), k.ctl(), k.estimate("*")]),
            rule(f"{p}-live", ["declare_liveliness_subscriber", "liveliness_query"],
                 [k.alive("*")]),
            rule(f"{p}-recover", ["put", "declare_queryable"], [adv(k.estimate(p))]),
            rule(f"{p}-ask", ["declare_subscriber", "query"],
                 [adv(k.scan(p)), adv(k.estimate("*"))]),
        ]
        subjects.append({"id": f"m-{p}", "cert_common_names": [p]})
        policies.append({"rules": [f"{p}-put", f"{p}-token", f"{p}-hear", f"{p}-live",
                                   f"{p}-recover", f"{p}-ask", "replies", "send"],
                         "subjects": [f"m-{p}"]})
    if routers:
        rules.append(rule("relay", ["put", "delete", "liveliness_token", "declare_subscriber",
                                    "declare_liveliness_subscriber", "liveliness_query",
                                    "reply", "query", "declare_queryable"],
                          [everything, recovery], flows=("ingress", "egress")))
        for r in routers:
            check_name(r, "router name")
            subjects.append({"id": f"m-{r}", "cert_common_names": [r]})
        policies.append({"rules": ["relay"], "subjects": [f"m-{r}" for r in routers]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


# -- secure mode ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Security:
    """One member's secure-mode settings: its folder, its name, the network's roster."""

    folder: Path
    member: str
    network: str
    peers: tuple[str, ...]
    world: str = WORLD
    routers: tuple[str, ...] = ()
    """Members named ``router*`` in the folder's ``members.json``: trusted to relay."""

    @classmethod
    def load(cls, folder: str | Path, member: str, network: str,
             peers: Sequence[str]) -> Security:
        """Check that ``folder`` holds the CA and ``member``'s key and certificate."""
        folder = Path(folder)
        need = [folder / CA_CERT, folder / f"{member}.pem", folder / f"{member}.key"]
        missing = [p.name for p in need if not p.is_file()]
        if missing:
            raise SecurityError(f"--secure {folder}: missing {', '.join(missing)} (make them "
                                f"with: sensornet keys {network} --out {folder} ...)")
        made_for = keys_network(folder)
        if made_for != network:
            raise SecurityError(f"--secure {folder}: keys of network {made_for!r}, not of "
                                f"{network!r} (use --network {made_for})")
        cn = common_name(folder / f"{member}.pem")
        if cn != member:
            raise SecurityError(f"{folder / (member + '.pem')} is the certificate of {cn!r}, "
                                f"not of {member!r}")
        roster = folder / "members.json"
        names = json.loads(roster.read_text()).get("members", []) if roster.is_file() else []
        routers = tuple(n for n in names if n.startswith(ROUTER_PREFIX))
        return cls(folder.resolve(), member, network, tuple(peers), routers=routers)

    @property
    def ca(self) -> Path:
        return self.folder / CA_CERT

    @property
    def cert(self) -> Path:
        return self.folder / f"{self.member}.pem"

    @property
    def key(self) -> Path:
        return self.folder / f"{self.member}.key"

    def signer(self):
        """This member's :class:`protocol.envelope.Signer` (its ``NAME.ed25519`` key), checked
        against the roster's public key for it."""
        from cryptography.hazmat.primitives.serialization import load_pem_private_key

        from protocol.envelope import Signer

        path = self.folder / f"{self.member}{SIGN_KEY}"
        hint = (f"add it with: sensornet keys {self.network} --out {self.folder} "
                f"--members {self.member}")
        if not path.is_file():
            raise SecurityError(f"--secure {self.folder}: no message-signing key "
                                f"{path.name} ({hint})")
        try:
            key = load_pem_private_key(path.read_bytes(), None)
        except ValueError as exc:
            raise SecurityError(f"{path}: not a private key ({exc})") from None
        listed = load_roster(self.folder).get(self.member)
        if listed is None or _public_b64(listed) != _public_b64(key.public_key()):
            raise SecurityError(f"{path} does not match {self.member}'s key in "
                                f"{self.folder / 'members.json'} ({hint})")
        return Signer(key)

    def verifier(self, senders: Sequence[str] | None = None):
        """A :class:`protocol.envelope.Verifier` holding the roster's keys; every name of
        ``senders`` (default: the world and every peer) must have one."""
        from protocol.envelope import Verifier

        roster = load_roster(self.folder)
        need = [self.world, *self.peers] if senders is None else list(senders)
        missing = [n for n in need if n not in roster]
        if missing:
            raise SecurityError(f"--secure {self.folder}: members.json has no signing key for "
                                f"{', '.join(missing)} (add them with: sensornet keys "
                                f"{self.network} --out {self.folder} --members "
                                f"{','.join(missing)})")
        return Verifier(roster, world=self.world)

    def apply(self, conf) -> None:
        """TLS certificates, mutual TLS and the access control policy on a Zenoh config."""
        tls = {"root_ca_certificate": str(self.ca),
               "listen_certificate": str(self.cert), "listen_private_key": str(self.key),
               "connect_certificate": str(self.cert), "connect_private_key": str(self.key),
               "enable_mtls": True}
        for name, value in tls.items():
            conf.insert_json5(f"transport/link/tls/{name}", json.dumps(value))
        conf.insert_json5("access_control", json.dumps(
            acl_rules(self.network, self.peers, self.world, self.routers)))


def tls_endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tls/{host}:{port}"


def check_endpoints(endpoints: Iterable[str]) -> None:
    """Secure mode speaks TLS only: a ``tcp/`` endpoint would bypass mutual TLS."""
    bad = [e for e in endpoints if not e.startswith("tls/")]
    if bad:
        raise SecurityError(f"secure mode needs tls/ endpoints, not {', '.join(bad)}")


# -- what the transport refused, counted where the peer can see it -----------------------------
ACL_LOG = "zenoh::net::routing::interceptor::access_control=trace"
"""Zenoh reports each refusal only as a trace line of its access-control module (the
publisher gets no error): a secure peer turns that module's trace on and counts the lines."""
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_CHECK = re.compile(r"(ThreadId\(\d+\)).*?access_control: (Using cached result: )?"
                    r"([0-9a-f]+)( on \S*?CertCommonName\(([^)]*)\))?.*? is (un)?authorized to "
                    r"(.+?) \((ingress|egress)\) on (\S+)")
_CACHE_GROUP = 9
"""Zenoh logs one line per message type (9) after "caching permissions for": not messages."""
_log_started = False


class RefusalLog:
    """Counts the access-control refusals of this process's Zenoh session.

    Zenoh writes its log to file descriptor 1; while running, this points descriptor 1 at a
    pipe, counts the refusal lines, and passes every other line on to the real stdout (the
    process's own prints go the same way, in order). ``counts()``: ``{"<sender> <message>
    <key>": n}`` for what arrived here and was refused (ingress).
    """

    def __init__(self) -> None:
        self._counts: dict[str, int] = {}
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._saved: int | None = None

    def start(self) -> RefusalLog:
        global _log_started
        import sys

        import zenoh

        sys.stdout.flush()
        r, w = os.pipe()
        self._saved = os.dup(1)
        os.dup2(w, 1)
        os.close(w)
        self._thread = threading.Thread(target=self._read, args=(r,), daemon=True,
                                        name="acl-log")
        self._thread.start()
        if not _log_started:
            zenoh.init_log_from_env_or(f"warn,{ACL_LOG}")
            _log_started = True
        return self

    def _read(self, r: int) -> None:
        skip: dict[str, int] = {}
        names: dict[str, str] = {}  # Zenoh id -> certificate common name
        out = self._saved
        with os.fdopen(r, "rb", buffering=0) as pipe:
            buf = b""
            while True:
                chunk = pipe.read(65536)
                if not chunk:
                    break
                buf += chunk
                *lines, buf = buf.split(b"\n")
                passed = []
                for raw in lines:
                    if b"interceptor::access_control" not in raw:
                        passed.append(raw)
                        continue
                    line = _ANSI.sub("", raw.decode("utf-8", "replace"))
                    if "caching permissions" in line:
                        m = re.search(r"(ThreadId\(\d+\))", line)
                        if m:
                            skip[m.group(1)] = _CACHE_GROUP
                        continue
                    m = _CHECK.search(line)
                    if m is None:
                        continue
                    thread, cached, zid, _, cn, un, what, flow, key = m.groups()
                    if cn:
                        names[zid] = cn
                    if not cached and skip.get(thread, 0) > 0:  # a cache entry, no message
                        skip[thread] -= 1
                        continue
                    if un and flow == "ingress":
                        who = names.get(zid, zid[:8])
                        label = f"{who} {what.replace('Declare/Undeclare ', '')} {key}"
                        with self._lock:
                            self._counts[label] = self._counts.get(label, 0) + 1
                if passed:
                    os.write(out, b"".join(p + b"\n" for p in passed))
            if buf:
                os.write(out, buf)

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())

    def stop(self) -> None:
        """Point descriptor 1 back at the real stdout and pass on what is left."""
        import sys

        if self._saved is None:
            return
        try:
            sys.stdout.flush()
        except Exception:
            pass
        os.dup2(self._saved, 1)  # closes the pipe's last write end: the reader drains, ends
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        os.close(self._saved)
        self._saved = None
