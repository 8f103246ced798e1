"""Who may speak on a network: secure mode for one member (mutual TLS, access control, signing).

The pieces, each in its own module and importable from here as well:

- :mod:`peers.member_keys`: ``sensornet keys NETWORK --out DIR`` (:func:`make_keys`) writes the
  network's CA and, per member (every peer and the world), a TLS key and certificate whose
  common name is the member's name, a message-signing key ``NAME.ed25519``, and the roster
  ``members.json`` (:func:`load_roster`);
- :mod:`peers.access_control`: the network's Zenoh access-control policy (:func:`acl_rules`);
- :mod:`peers.refusal_log`: the refusals the transport counts (:class:`RefusalLog`).

A member process in secure mode (``--secure DIR``, :class:`Security`) builds its Zenoh session
with ``tls/`` endpoints, mutual TLS against the network's CA only, and the network's access
control policy (:func:`acl_rules`, default deny, subjects by certificate common name): a peer
may put only on its own ``estimate/`` and ``tracks/`` keys and declare only its own ``alive/``
and ``ready/`` liveliness tokens; only the world may put ``scan/``, ``truth`` and ``ctl``.
Zenoh applies the policy where a message *arrives* (each member filters what it receives), so
every member loads the same policy: a member that lies about whose key it puts on is refused
by every other member, whatever its own process does. On top of that every message is signed by
its sender's Ed25519 key and checked by each receiver against the roster, with replays refused
(:mod:`protocol.envelope`): what a router relays or a recording holds still names its sender.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from sensornet.peers.access_control import OBSERVER, OBSERVER_PREFIX, ROUTER_PREFIX, acl_rules
from sensornet.peers.endpoints import check_endpoints, tls_endpoint
from sensornet.peers.member_keys import (
    CA_CERT,
    CA_KEY,
    DEFAULT_HOSTS,
    SIGN_KEY,
    SIGNING,
    WORLD,
    SecurityError,
    _public_b64,
    check_private,
    common_name,
    keys_network,
    load_roster,
    make_keys,
)
from sensornet.peers.refusal_log import ACL_LOG, RefusalLog
from sensornet.protocol.envelope import Signer, Verifier


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
    observers: tuple[str, ...] = ()
    """Members named ``view*`` there: read-only (they may subscribe, not put)."""

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
        check_private(folder / f"{member}.key")  # Zenoh reads it: check it first
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
        observers = tuple(n for n in names if n.startswith(OBSERVER_PREFIX) and n not in peers)
        return cls(folder.resolve(), member, network, tuple(peers), routers=routers,
                   observers=observers)

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
        # heavy dependency: cryptography (peers.member_keys: secure runs only)
        from cryptography.hazmat.primitives.serialization import load_pem_private_key

        path = self.folder / f"{self.member}{SIGN_KEY}"
        hint = (f"add it with: sensornet keys {self.network} --out {self.folder} "
                f"--members {self.member}")
        if not path.is_file():
            raise SecurityError(f"--secure {self.folder}: no message-signing key "
                                f"{path.name} ({hint})")
        try:
            key = load_pem_private_key(check_private(path).read_bytes(), None)
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
            acl_rules(self.network, self.peers, self.world, self.routers, self.observers)))


__all__ = ["ACL_LOG", "CA_CERT", "CA_KEY", "DEFAULT_HOSTS", "OBSERVER", "ROUTER_PREFIX", "SIGNING",
           "SIGN_KEY", "WORLD", "RefusalLog", "Security", "SecurityError", "acl_rules",
           "check_endpoints", "check_private", "common_name", "keys_network", "load_roster",
           "make_keys", "tls_endpoint"]
