"""Each service's own credentials out of the vault, and a user's files checked (issue 25 item 7; docs/semantics.md §7).

The *vault* is the folder :mod:`services.common.security` fills: every password,
the CA with its key, one certificate per name and, on a fleet's hub, ``fleet/``.
No running service mounts it.  :func:`hand_out` copies into each service's own
folder only what that service presents or checks:

- ``router``: ``users.txt`` (its ``dictionary_file``), ``tls/ca.pem``,
  ``tls/router.pem``, ``tls/router.key``; on a hub also ``fleet/ca.pem``,
  ``fleet/hub.pem``, ``fleet/hub.key`` and ``fleet/hub.password`` (its links);
- user ``U`` (a client): ``U.password``, ``tls/ca.pem``, ``tls/U.pem``, ``tls/U.key``.

Never ``ca.key``.  A client's folder holds nothing else (other files there are
removed); the router's keeps what it writes itself (a fleet's ``hub/``,
``tls/trusted.pem``).  :func:`client_files` checks a user's files (a hand-out
or a vault) before ``skinet client-config`` names them in a Zenoh configuration.
Cost: a few kilobytes read and compared per service.
"""

from __future__ import annotations

import datetime
import os
import stat
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import NameOID

from services.common.security import FLEET, USERS, write_file
from skinet.errors import SkinetError
from skinet.files.read import FileRefused, read_bytes

ROUTER = "router"
MAX_SECRET_FILE = 1 << 20  # bytes: a password, a certificate chain or a key is a few KiB
CLIENT_LAYOUT = "<user>.password, tls/ca.pem, tls/<user>.pem and tls/<user>.key"


def service_files(vault: Path, name: str) -> list[str]:
    """The files (relative to the vault) that service ``name`` gets: ``router`` or a user."""
    if name == ROUTER:
        files = ["users.txt", "tls/ca.pem", "tls/router.pem", "tls/router.key"]
        if (vault / FLEET / "hub.pem").exists():
            files += [f"{FLEET}/ca.pem", f"{FLEET}/hub.pem", f"{FLEET}/hub.key", f"{FLEET}/hub.password"]
        return files
    return [f"{name}.password", "tls/ca.pem", f"tls/{name}.pem", f"tls/{name}.key"]


def _copy(source: Path, target: Path, out: Path) -> None:
    """``target`` (below ``out``) with ``source``'s bytes, 0644 for certificates and 0600 for the
    rest, written afresh through no link (:func:`services.common.security.write_file`)."""
    try:
        write_file(target, source.read_bytes(), 0o644 if target.suffix == ".pem" else 0o600, base=out)
    except OSError as exc:
        raise SkinetError(f"cannot write {target}: {exc.strerror}") from None


def _remove_strays(folder: Path, keep: list[str]) -> None:
    """Remove every file of ``folder`` but ``keep``, walking by descriptors (``os.fwalk``): a
    link in the folder is removed itself, never followed."""
    for root, _, files, root_fd in os.fwalk(folder, follow_symlinks=False):
        for name in files:
            if os.path.relpath(os.path.join(root, name), folder) not in keep:
                os.unlink(name, dir_fd=root_fd)


def hand_out(vault: Path, out: Path, withheld: frozenset[str] = frozenset()) -> dict[str, list[str]]:
    """Copy each service's files from ``vault`` into ``out/<service>`` for every folder
    already in ``out`` (compose mounts one volume there per service); returns what each got.
    The folders named in ``withheld`` get nothing and are emptied (a login not switched on).

    Nothing is written through a link: a link as a service's folder, as ``tls/`` or
    ``fleet/`` in it, or at a file's name is refused (:class:`SkinetError`, one line)
    and the vault is left as it was."""
    handed: dict[str, list[str]] = {}
    for folder in sorted(p for p in out.iterdir() if p.is_dir() or p.is_symlink()):
        if folder.name != ROUTER and folder.name not in USERS:
            raise SkinetError(f"{folder}: a service's folder is named {ROUTER} or for its user ({', '.join(USERS)})")
        if folder.name in withheld:
            if not folder.is_symlink():
                _remove_strays(folder, [])
            handed[folder.name] = []
            continue
        files = service_files(vault, folder.name)
        missing = [f for f in files if not (vault / f).is_file()]
        if missing:
            raise SkinetError(f"{vault} has no {', '.join(missing)} for {folder.name}")
        for name in files:
            _copy(vault / name, folder / name, out)
        if folder.name != ROUTER:
            _remove_strays(folder, files)
        handed[folder.name] = files
    return handed


def take_handed(handed: Path, folder: Path) -> list[str]:
    """Copy every regular file below ``handed`` (the router's hand-out, mounted read-only)
    into ``folder`` (the router's own, writable), through no link; returns the names.

    The job writes into a folder the router cannot write, and the router keeps its
    own state (``hub/``, ``robots/``, ``tls/trusted.pem``, ``users.txt`` with a
    fleet's ``hub`` password) in a folder the job never writes (docs/deployment.md,
    "Secrets").  Links in ``handed`` are skipped, not followed.  Cost: the files' bytes.
    """
    if not handed.is_dir():
        raise SkinetError(f"handed-out secrets folder {handed} does not exist")
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    copied = []
    for root, _, files, root_fd in os.fwalk(handed, follow_symlinks=False):
        for name in sorted(files):
            st = os.stat(name, dir_fd=root_fd, follow_symlinks=False)
            if not stat.S_ISREG(st.st_mode):
                continue
            fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, dir_fd=root_fd)
            with os.fdopen(fd, "rb") as f:
                data = f.read()
            relative = os.path.relpath(os.path.join(root, name), handed)
            write_file(folder / relative, data, stat.S_IMODE(st.st_mode) & 0o644, base=folder)
            copied.append(relative)
    return sorted(copied)


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
