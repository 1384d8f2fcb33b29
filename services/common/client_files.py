"""A user's secrets checked as the router will check them, and the Zenoh configuration that presents them
(docs/deployment.md, TLS): what ``skinet client-config`` and the views' logins read from a hand-out or a vault
(:mod:`services.secrets.handout`).  Cost: a few kilobytes read, one signature verified.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import NameOID

from skinet.errors import SkinetError
from skinet.files.read import FileRefused, read_bytes

MAX_SECRET_FILE = 1 << 20  # bytes: a password, a certificate chain or a key is a few KiB
CLIENT_LAYOUT = "<user>.password, tls/ca.pem, tls/<user>.pem and tls/<user>.key"


@dataclass(frozen=True)
class ClientFiles:
    """What a client of user ``user`` presents to the router: password, CA, certificate, key."""

    user: str
    password: str
    ca: Path
    certificate: Path
    key: Path


def _read(path: Path, user: str) -> bytes:
    if not path.exists():
        raise SkinetError(f"{path} is missing (the secrets of user '{user}' are {CLIENT_LAYOUT.replace('<user>', user)})")
    try:
        return read_bytes(path, MAX_SECRET_FILE)[0]
    except FileRefused as exc:  # a FIFO, a huge file: refused, never waited on
        raise SkinetError(f"cannot read {path}: {exc.reason.removeprefix('cannot read file: ')}") from None


def _certificate(path: Path, user: str) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(_read(path, user))
    except ValueError:
        raise SkinetError(f"{path} is not a PEM certificate") from None


def client_files(folder: Path, user: str, now: datetime.datetime | None = None) -> ClientFiles:
    """``user``'s files in ``folder``, checked as the router will: the certificate names
    ``user`` (the router's access control binds certificates to users), is signed by
    ``tls/ca.pem``, is valid now and matches its key.  :class:`SkinetError` (one line) otherwise."""
    if not folder.is_dir():
        raise SkinetError(f"secrets folder {folder} does not exist")
    tls = folder / "tls"
    if (folder / "users.txt").is_file() and not tls.is_dir():  # a router's folder, from a router with no tls/
        raise SkinetError(f"{folder} has no tls/ folder: a router makes its certificates there when it listens on a "
                          "tls/ endpoint (skinet router --secrets DIR --listen tls/0.0.0.0:7447)")
    password = _read(folder / f"{user}.password", user).decode(errors="replace").strip()
    if not password or "\n" in password:
        raise SkinetError(f"{folder / f'{user}.password'} must hold the password on one line")
    ca = _certificate(tls / "ca.pem", user)
    cert_path = tls / f"{user}.pem"
    cert = _certificate(cert_path, user)
    names = [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)]
    if names != [user]:
        raise SkinetError(f"{cert_path} is the certificate of {', '.join(map(repr, names)) or 'nobody'}, not of "
                          f"user '{user}': the router accepts each user with its own certificate only")
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise SkinetError(f"{cert_path} is not signed by the CA of {tls / 'ca.pem'}") from None
    now = now or datetime.datetime.now(datetime.timezone.utc)
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise SkinetError(f"{cert_path} is valid from {cert.not_valid_before_utc:%Y-%m-%d} to "
                          f"{cert.not_valid_after_utc:%Y-%m-%d} only (a new one: docs/deployment.md, TLS)")
    key_path = tls / f"{user}.key"
    try:
        key = serialization.load_pem_private_key(_read(key_path, user), None)
    except (ValueError, TypeError):
        raise SkinetError(f"{key_path} is not an unencrypted PEM private key") from None
    spki = serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    if key.public_key().public_bytes(*spki) != cert.public_key().public_bytes(*spki):
        raise SkinetError(f"{key_path} is not the key of {cert_path}")
    return ClientFiles(user, password, (tls / "ca.pem").resolve(), cert_path.resolve(), key_path.resolve())


def client_config(files: ClientFiles, endpoint: str) -> dict:
    """The Zenoh configuration of a client logging in as ``files.user`` at ``endpoint`` over mutual TLS."""
    return {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "auth": {"usrpwd": {"user": files.user, "password": files.password}},
            "link": {"tls": {"root_ca_certificate": str(files.ca), "enable_mtls": True,
                             "connect_certificate": str(files.certificate),
                             "connect_private_key": str(files.key)}},
        },
    }
