"""A network's member keys: its CA, a TLS key and certificate per member, the signing roster.

``sensornet keys NETWORK --out DIR`` (:func:`make_keys`) writes a network CA and, per member
(every peer and the world), a private key and a certificate whose common name is the member's
name, all plain PEM files (``openssl x509 -in DIR/s1.pem -noout -text`` reads them):

    DIR/ca.pem  DIR/ca.key          the network's CA (keep ca.key off the members' machines)
    DIR/<name>.pem  DIR/<name>.key  one per member: CN=<name>, O=<network>, signed by the CA
    DIR/<name>.ed25519              one per member: its message-signing key (Ed25519)
    DIR/members.json                the roster: member names and signing public keys

:func:`load_roster` reads the signing public keys back, :func:`keys_network` and
:func:`common_name` what a folder's CA and a member's certificate name. How a member uses the
folder in secure mode is :class:`peers.security.Security`.
"""

from __future__ import annotations

import base64
import contextlib
import datetime
import ipaddress
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from sensornet.peers.errors import SecurityError
from sensornet.protocol.keys import WORLD, check_name  # noqa: F401  (WORLD: re-exported)

CA_CERT, CA_KEY = "ca.pem", "ca.key"
SIGN_KEY = ".ed25519"
"""Suffix of a member's message-signing private key (``NAME.ed25519``, PEM PKCS#8)."""
SIGNING = "ed25519"
"""Field of ``members.json`` holding the roster: member name -> signing public key."""
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
"""Names every member certificate is valid for (the host part of the endpoints dialled)."""




# -- keys and certificates --------------------------------------------------------------------
def _name(cn: str, org: str | None = None):
    # heavy dependency: cryptography (its OpenSSL bindings load only for secure runs)
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    attrs = [x509.NameAttribute(NameOID.COMMON_NAME, cn)]
    if org:
        attrs.append(x509.NameAttribute(NameOID.ORGANIZATION_NAME, org))
    return x509.Name(attrs)


def _write(path: Path, data: bytes, private: bool = False) -> None:
    """Write ``path`` atomically: a fresh temporary file beside it (``tempfile.mkstemp``: a
    random name, created exclusively, never through a symlink, mode 0600), then
    ``os.replace``. No fixed ``NAME.tmp`` name, so neither a leftover file (its mode kept by
    ``O_TRUNC``) nor a planted symlink there decides where or how a key is written. Public
    files (certificates, the roster) are made 0644 before they take their name."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            if not private:
                os.fchmod(fh.fileno(), 0o644)
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def check_private(path: Path) -> Path:
    """Refuse a private key file that is a symbolic link, not a regular file, or readable or
    writable by the group or others (as ssh does): one line saying which file and what to do.
    """
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise SecurityError(f"{path}: no such private key file") from None
    if stat.S_ISLNK(st.st_mode):
        raise SecurityError(f"{path} is a symbolic link: a private key must be the file itself "
                            f"(copy it there, then: chmod 600 {path})")
    if not stat.S_ISREG(st.st_mode):
        raise SecurityError(f"{path} is not a regular file: a private key must be one")
    if st.st_mode & 0o077:
        raise SecurityError(f"{path} is accessible by others (mode "
                            f"{stat.S_IMODE(st.st_mode):04o}); a private key must be readable "
                            f"by its owner only: chmod 600 {path}")
    return path


def _read_private(path: Path) -> bytes:
    """A private key file's bytes, after :func:`check_private`."""
    return check_private(path).read_bytes()


def _san(hosts: Iterable[str]):
    # heavy dependency: cryptography, as above
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
    members = _checked_members(network, members)
    out.mkdir(mode=0o700, parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    valid = (now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=days))
    ca_key, ca_cert = _network_ca(network, out, valid)
    written = [out / CA_CERT, out / CA_KEY]
    for m in members:
        key_path, cert_path = out / f"{m}.key", out / f"{m}.pem"
        if key_path.exists() and cert_path.exists() and not overwrite:
            check_private(key_path)  # kept: it must still be private
        else:
            _member_certificate(m, network, ca_key, ca_cert, valid, hosts, key_path, cert_path)
        written += [cert_path, key_path]
    return [*written, *_signing_keys(network, members, out, overwrite)]


def _checked_members(network: str, members: Sequence[str]) -> list[str]:
    """``members`` without repeats, every name (and the network's) checked."""
    check_name(network, "network name")
    members = list(dict.fromkeys(members))
    if not members:
        raise SecurityError("no members: give --members a,b,c or --scenario")
    for m in members:
        check_name(m, "member name")
    if any(m.lower() == CA_CERT.removesuffix(".pem") for m in members):
        raise SecurityError("'ca' cannot be a member name (it is the CA's file)")
    return members


def _pem_private(key) -> bytes:
    """A private key as unencrypted PKCS#8 PEM (what every member file holds)."""
    # heavy dependency: cryptography, as in _name
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _network_ca(network: str, out: Path, valid: tuple) -> tuple:
    """``(key, certificate)`` of the network's CA in ``out``: the one there (it must be this
    network's), or a new one valid over ``valid = (start, end)``, written."""
    # heavy dependency: cryptography, as in _name
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    ca_cert_path, ca_key_path = out / CA_CERT, out / CA_KEY
    if ca_cert_path.exists() and ca_key_path.exists():
        ca_key = serialization.load_pem_private_key(_read_private(ca_key_path), None)
        ca_cert = x509.load_pem_x509_certificate(ca_cert_path.read_bytes())
        org = ca_cert.subject.get_attributes_for_oid(x509.oid.NameOID.ORGANIZATION_NAME)
        if not org or org[0].value != network:
            raise SecurityError(f"{out} holds the CA of another network "
                                f"({org[0].value if org else '?'!r}); use another folder")
        return ca_key, ca_cert
    ca_key = ec.generate_private_key(ec.SECP256R1())
    subject = _name(f"sensornet {network} CA", network)
    ca_cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
               .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
               .not_valid_before(valid[0]).not_valid_after(valid[1])
               .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
               .add_extension(x509.KeyUsage(
                   digital_signature=False, content_commitment=False,
                   key_encipherment=False, data_encipherment=False, key_agreement=False,
                   key_cert_sign=True, crl_sign=True, encipher_only=False,
                   decipher_only=False), critical=True)
               .add_extension(x509.SubjectKeyIdentifier.from_public_key(
                   ca_key.public_key()), critical=False)
               .sign(ca_key, hashes.SHA256()))
    _write(ca_key_path, _pem_private(ca_key), private=True)
    _write(ca_cert_path, ca_cert.public_bytes(serialization.Encoding.PEM))
    return ca_key, ca_cert


def _member_certificate(member: str, network: str, ca_key, ca_cert, valid: tuple,
                        hosts: Sequence[str], key_path: Path, cert_path: Path) -> None:
    """Write a new key and CA-signed certificate for ``member``: serverAuth and clientAuth,
    ``hosts`` as SANs, valid over ``valid = (start, end)``."""
    # heavy dependency: cryptography, as in _name
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder().subject_name(_name(member, network))
            .issuer_name(ca_cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(valid[0]).not_valid_after(valid[1])
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
    _write(key_path, _pem_private(key), private=True)
    _write(cert_path, cert.public_bytes(serialization.Encoding.PEM))


def _signing_keys(network: str, members: list[str], out: Path, overwrite: bool) -> list[Path]:
    """The members' message-signing keys (Ed25519: made where missing, or rotated with
    ``overwrite``) and the roster ``members.json`` with their public halves; their paths."""
    # heavy dependency: cryptography, as in _name
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    roster = out / "members.json"
    known = json.loads(roster.read_text()) if roster.exists() else {}
    signing = dict(known.get(SIGNING, {}))
    written = []
    for m in members:
        sign_path = out / f"{m}{SIGN_KEY}"
        if overwrite or not sign_path.is_file():
            _write(sign_path, _pem_private(Ed25519PrivateKey.generate()), private=True)
        signing[m] = _public_b64(serialization.load_pem_private_key(
            _read_private(sign_path), None).public_key())
        written.append(sign_path)
    _write(roster, json.dumps({"network": network,
                               "members": list(dict.fromkeys([*known.get("members", []),
                                                              *members])),
                               SIGNING: signing}, indent=1).encode())
    return [*written, roster]


def _public_b64(public_key) -> str:
    """An Ed25519 public key as the base64 of its DER SubjectPublicKeyInfo: the one line
    between the PEM markers of ``openssl pkey -in NAME.ed25519 -pubout``."""
    # heavy dependency: cryptography, as in _name
    from cryptography.hazmat.primitives import serialization

    der = public_key.public_bytes(serialization.Encoding.DER,
                                  serialization.PublicFormat.SubjectPublicKeyInfo)
    return base64.b64encode(der).decode()


def load_roster(folder: str | Path) -> dict:
    """The members' message-signing public keys from ``members.json`` (name -> key)."""
    # heavy dependency: cryptography, as in _name
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
    # heavy dependency: cryptography, as above
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
    # heavy dependency: cryptography, as above
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    cert = x509.load_pem_x509_certificate(Path(cert_path).read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)
