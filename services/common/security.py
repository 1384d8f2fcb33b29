"""Secrets and certificates for a deployment, made at first start (issue 14; SPEC §7).

Nothing that works is committed: :func:`ensure_users` writes a random password per
user (``users.txt`` for the router's ``dictionary_file``, ``<user>.password`` for
each service) and :func:`ensure_tls` a certificate authority with one certificate
per name (``ca.pem``; ``<name>.pem`` and ``<name>.key``), with the well-kept
``cryptography`` library.  Both keep what already exists, so an operator may put
their own files there first, and both are idempotent: the router's entry point and
``skinet router`` call them at every start.  :func:`make_certificate` also makes
expired or foreign certificates for tests.  Files are written 0600 (0644 for
``ca.pem`` and certificates).

Reusable by any deployment (a fleet of routers): ``ensure_tls(folder, ["router",
"robot1-router", ...])`` gives every name a certificate for the DNS name
``name`` and ``localhost``/``127.0.0.1``.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import secrets
from collections.abc import Iterable
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

USERS = ("bridge", "monitor", "predictor", "robot", "observer", "hub")
DAY = datetime.timedelta(days=1)


def _write(path: Path, data: bytes, mode: int = 0o600) -> None:
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(tmp, mode)
    tmp.replace(path)


def ensure_users(folder: Path, users: Iterable[str] = USERS) -> dict[str, str]:
    """``folder/users.txt`` and ``folder/<user>.password`` for every user; returns user -> password.

    Existing entries are kept; missing users get a random 24-byte password.
    """
    folder.mkdir(parents=True, exist_ok=True)
    table = folder / "users.txt"
    known: dict[str, str] = {}
    if table.exists():
        for line in table.read_text().splitlines():
            if ":" in line:
                user, password = line.split(":", 1)
                known[user] = password
    changed = False
    for user in users:
        if user not in known:
            known[user] = secrets.token_urlsafe(24)
            changed = True
        path = folder / f"{user}.password"
        if not path.exists() or path.read_text().strip() != known[user]:
            _write(path, known[user].encode() + b"\n", 0o644 if user == "observer" else 0o600)
    if changed or not table.exists():
        _write(table, "".join(f"{u}:{p}\n" for u, p in known.items()).encode())
    return known


def _key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def make_ca(folder: Path, name: str = "SkiNet Live CA", days: int = 3650) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    """A self-signed certificate authority: ``folder/ca.pem`` and ``folder/ca.key``."""
    folder.mkdir(parents=True, exist_ok=True)
    key = _key()
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - DAY)
            .not_valid_after(now + days * DAY)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False),
                           critical=True)
            .sign(key, hashes.SHA256()))
    _write(folder / "ca.pem", cert.public_bytes(serialization.Encoding.PEM), 0o644)
    _write(folder / "ca.key", _pem_key(key))
    return cert, key


def load_ca(folder: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    cert = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), None)
    assert isinstance(key, ec.EllipticCurvePrivateKey), "ca.key must be an EC key"
    return cert, key


def make_certificate(folder: Path, name: str, ca: tuple[x509.Certificate, ec.EllipticCurvePrivateKey], *,
                     days: int = 825, expired: bool = False, hostnames: Iterable[str] = ()) -> Path:
    """``folder/<name>.pem`` (leaf then CA) and ``folder/<name>.key`` for server and client use.

    The certificate names ``name``, ``hostnames``, ``localhost`` and ``127.0.0.1``;
    ``expired`` makes one that expired yesterday (tests).
    """
    ca_cert, ca_key = ca
    key = _key()
    now = datetime.datetime.now(datetime.timezone.utc)
    start, end = (now - 10 * DAY, now - DAY) if expired else (now - DAY, now + days * DAY)
    sans: list[x509.GeneralName] = []
    for host in dict.fromkeys([name, *hostnames, "localhost", "127.0.0.1"]):
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            sans.append(x509.DNSName(host))
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_cert.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(end)
            .add_extension(x509.SubjectAlternativeName(sans), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))
    folder.mkdir(parents=True, exist_ok=True)
    chain = cert.public_bytes(serialization.Encoding.PEM) + ca_cert.public_bytes(serialization.Encoding.PEM)
    _write(folder / f"{name}.pem", chain, 0o644)
    _write(folder / f"{name}.key", _pem_key(key))
    return folder / f"{name}.pem"


def ensure_tls(folder: Path, names: Iterable[str], hostnames: Iterable[str] = ()) -> None:
    """A CA in ``folder`` (made if missing) and a certificate for each name that has none;
    ``hostnames`` (addresses clients use, e.g. ``robot.example``) go into every new one."""
    ca = load_ca(folder) if (folder / "ca.pem").exists() and (folder / "ca.key").exists() else make_ca(folder)
    for name in names:
        if not (folder / f"{name}.pem").exists() or not (folder / f"{name}.key").exists():
            make_certificate(folder, name, ca, hostnames=hostnames)


def tls_listen_config(folder: Path, name: str) -> dict:
    """The ``transport/link/tls`` section of a router serving ``name``'s certificate and
    requiring clients to present one signed by the CA (mutual TLS)."""
    return {"root_ca_certificate": str(folder / "ca.pem"), "listen_certificate": str(folder / f"{name}.pem"),
            "listen_private_key": str(folder / f"{name}.key"), "enable_mtls": True,
            "connect_certificate": str(folder / f"{name}.pem"), "connect_private_key": str(folder / f"{name}.key")}


def tls_connect_config(folder: Path, name: str) -> dict:
    """The ``transport/link/tls`` section of a client presenting ``name``'s certificate."""
    return {"root_ca_certificate": str(folder / "ca.pem"), "enable_mtls": True,
            "connect_certificate": str(folder / f"{name}.pem"), "connect_private_key": str(folder / f"{name}.key")}
