"""Secrets and certificates for a deployment, made at first start (issue 14; docs/semantics.md §7).

Nothing that works is committed: :func:`ensure_users` writes a random password per
user (``users.txt`` for the router's ``dictionary_file``, ``<user>.password`` for
each service) and :func:`ensure_tls` a certificate authority with one certificate
per name (``ca.pem``; ``<name>.pem`` and ``<name>.key``), with the well-kept
``cryptography`` library.  Both keep what already exists, so an operator may put
their own files there first, and both are idempotent: the compose job ``secrets``
(:mod:`services.secrets`) and ``skinet router`` call them at every start.
:func:`make_certificate` also makes expired or foreign certificates for tests.
Secret files (passwords, ``users.txt``, keys) are 0600, and made so again at the
next start when found looser; certificates and ``ca.pem`` are 0644.  A certificate
is made only where the CA key is: :func:`ensure_tls` refuses a folder that has
``ca.pem`` without ``ca.key`` instead of making a new CA over it.

Reusable by any deployment (a fleet of routers): ``ensure_tls(folder, ["router",
"robot1-router", ...])`` gives every name a certificate for the DNS name
``name`` and ``localhost``/``127.0.0.1``.

A fleet (issue 15; docs/deployment.md, "Fleet") links one off-board router, the
hub, to every robot's router over mutual TLS.  Each robot keeps its own CA and
passwords; the hub makes a *fleet CA* (``fleet/``) that signs only the hub's link
certificate, and one password for the user ``hub``.  The operator carries two
things: the hub's invitation (:func:`fleet_invitation`: the fleet CA and the hub
password, the same for every robot) to each robot (:func:`join_fleet`: the robot's
router then trusts the fleet CA and takes that password for ``hub``), and each
robot's ``ca.pem`` (public) back to the hub (:func:`add_robot`), which trusts it
for that robot's link only (:func:`hub_endpoints`).
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
import re
import secrets
import stat
from collections.abc import Iterable
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from skinet.errors import SkinetError

USERS = ("bridge", "monitor", "predictor", "robot", "observer", "hub", "pilot", "operator", "goalbox")
DAY = datetime.timedelta(days=1)


class LinkRefused(SkinetError):
    """A secret would have been written through a link, or over what is not a file."""


_NOFOLLOW_DIR = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC


def _open_folder(folder: Path, base: Path | None) -> int:
    """A descriptor of ``folder``, opened without following a link: ``folder`` itself
    and, with ``base``, every folder below ``base`` on the way (made 0700 when missing).
    ``base`` is trusted (opened as it is named)."""
    if base is None:
        return _open_part(folder, None, folder)
    fd = os.open(base, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        here = base
        for part in folder.relative_to(base).parts:
            here = here / part
            try:
                os.mkdir(part, 0o700, dir_fd=fd)
            except FileExistsError:
                pass
            inner = _open_part(Path(part), fd, here)
            os.close(fd)
            fd = inner
        return fd
    except BaseException:
        os.close(fd)
        raise


def _open_part(name: Path, dir_fd: int | None, shown_as: Path) -> int:
    try:
        return os.open(name, _NOFOLLOW_DIR, dir_fd=dir_fd)
    except OSError:
        if os.path.islink(shown_as):
            raise LinkRefused(f"{shown_as} is a link: secrets are never written through a link") from None
        raise


def write_file(path: Path, data: bytes, mode: int = 0o600, base: Path | None = None) -> None:
    """``path`` with ``data`` and ``mode`` (0600 by default), replaced at once: never half written
    nor, for a moment, readable by others, and never through a link.

    The folder is opened without following a link (with ``base``: every folder from
    ``base`` down, made when missing); the data goes to a new file of a random name
    there, made exclusively (``O_CREAT|O_EXCL|O_NOFOLLOW``), then renamed over
    ``path``.  A link (or anything but a regular file) at ``path`` or as its folder is
    refused: :class:`LinkRefused`, nothing written.  Cost: a few system calls and the write.
    """
    fd = _open_folder(path.parent, base)
    tmp = f".{path.name}.{secrets.token_hex(8)}.tmp"
    try:
        try:
            st = os.stat(path.name, dir_fd=fd, follow_symlinks=False)
        except FileNotFoundError:
            st = None
        if st is not None and stat.S_ISLNK(st.st_mode):
            raise LinkRefused(f"{path} is a link: secrets are never written through a link")
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise LinkRefused(f"{path} is not a regular file: a secret is written as a file only")
        out = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode, dir_fd=fd)
        try:
            with os.fdopen(out, "wb", closefd=False) as f:
                f.write(data)
            os.fchmod(out, mode)  # the umask may have narrowed or the old file widened it
        finally:
            os.close(out)
        os.rename(tmp, path.name, src_dir_fd=fd, dst_dir_fd=fd)  # a link put there since is replaced, not followed
    except BaseException:
        try:
            os.unlink(tmp, dir_fd=fd)
        except OSError:
            pass
        raise
    finally:
        os.close(fd)


def private(path: Path) -> None:
    """Make an existing secret file 0600 if group or others may read it (files of older versions);
    a link or what is not a regular file is left alone (its mode is not the file's to change)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return
    try:
        st = os.fstat(fd)
        if stat.S_ISREG(st.st_mode) and st.st_mode & 0o077:
            os.fchmod(fd, 0o600)
    finally:
        os.close(fd)


def new_password() -> str:
    """A random 24-byte password (URL-safe base64) that does not start with ``-``: given after ``--password`` on a
    command line, one that did would be taken for an option."""
    while (password := secrets.token_urlsafe(24)).startswith("-"):
        pass
    return password


def ensure_users(folder: Path, users: Iterable[str] = USERS, fixed: dict[str, str] | None = None,
                 password_files: bool = True) -> dict[str, str]:
    """``folder/users.txt`` and, with ``password_files``, ``folder/<user>.password`` for every
    user; returns user -> password.

    Existing entries are kept, except those of ``fixed`` (user -> password, e.g. the
    fleet's ``hub`` password), which replace them; missing users get a random 24-byte password.
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
    for user, password in (fixed or {}).items():
        if known.get(user) != password:
            known[user] = password
            changed = True
    for user in users:
        if user not in known:
            known[user] = new_password()
            changed = True
        path = folder / f"{user}.password"
        if not password_files:
            continue
        if not path.exists() or path.read_text().strip() != known[user]:
            write_file(path, known[user].encode() + b"\n")
        private(path)
    if changed or not table.exists():
        write_file(table, "".join(f"{u}:{p}\n" for u, p in known.items()).encode())
    private(table)
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
    write_file(folder / "ca.pem", cert.public_bytes(serialization.Encoding.PEM), 0o644)
    write_file(folder / "ca.key", _pem_key(key))
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
    write_file(folder / f"{name}.pem", chain, 0o644)
    write_file(folder / f"{name}.key", _pem_key(key))
    return folder / f"{name}.pem"


def ensure_tls(folder: Path, names: Iterable[str], hostnames: Iterable[str] = ()) -> None:
    """A certificate in ``folder`` for each name that has none, signed by the CA there
    (made with the first certificate when ``folder`` has no ``ca.pem``); ``hostnames``
    (addresses clients use, e.g. ``robot.example``) go into every new one.

    The CA key is read only when a certificate is missing; :class:`SkinetError` when
    one is and ``folder`` holds ``ca.pem`` without ``ca.key`` (a router's or a
    client's handed-out files, or an operator's own CA): a new CA would silently
    replace the one every other party trusts.
    """
    names = list(names)
    missing = [n for n in names if not (folder / f"{n}.pem").exists() or not (folder / f"{n}.key").exists()]
    for key in [folder / "ca.key", *(folder / f"{n}.key" for n in names if n not in missing)]:
        if key.exists():
            private(key)
    if not missing:
        return
    if (folder / "ca.pem").exists() and not (folder / "ca.key").exists():
        raise SkinetError(f"{folder} has ca.pem but no ca.key: cannot make the certificate of "
                          f"{', '.join(missing)} (make it where the CA key is: docs/deployment.md, TLS)")
    ca = load_ca(folder) if (folder / "ca.pem").exists() else make_ca(folder)
    for name in missing:
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


# -- fleet: the hub's links to the robots' routers (issue 15) --------------------------

FLEET = "fleet"    # on the hub: the fleet CA, the hub's link certificate and hub.password
JOINED = "hub"     # on a robot: the hub's fleet CA and password (join_fleet)
ROBOTS = "robots"  # on the hub: robots/<host>.pem, each robot's CA (add_robot)
_HOST = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?$")


class FleetError(SkinetError):
    """Bad fleet input (an invitation, a CA, a robot endpoint): one line."""


def ensure_fleet(folder: Path) -> str:
    """The hub's side: a fleet CA with the certificate ``hub`` in ``folder/fleet`` and
    ``folder/fleet/hub.password``, made when missing; returns the password."""
    fleet = folder / FLEET
    ensure_tls(fleet, ["hub"])
    path = fleet / "hub.password"
    if not path.exists():
        write_file(path, new_password().encode() + b"\n")
    private(path)
    return path.read_text().strip()


def fleet_invitation(folder: Path) -> str:
    """What every robot needs from the hub, one JSON line: the fleet CA and the hub's password."""
    password = ensure_fleet(folder)
    return json.dumps({"fleet_ca": (folder / FLEET / "ca.pem").read_text(), "hub_password": password})


def _ca_pem(text: str, what: str) -> x509.Certificate:
    try:
        cert = x509.load_pem_x509_certificate(text.encode())
    except ValueError:
        raise FleetError(f"{what} is not a PEM certificate") from None
    try:
        ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        ca = False
    if not ca:
        raise FleetError(f"{what} is not a CA certificate (BasicConstraints CA:TRUE)")
    return cert


def join_fleet(folder: Path, invitation: str) -> str:
    """The robot's side: keep the hub's invitation in ``folder/hub`` (read by
    :func:`robot_fleet`, i.e. at the router's next start); returns the robot's own
    ``tls/ca.pem`` for :func:`add_robot` on the hub."""
    try:
        data = json.loads(invitation)
        ca, password = data["fleet_ca"], data["hub_password"]
    except (ValueError, TypeError, KeyError):
        raise FleetError("the invitation is not the output of `skinet fleet invite` "
                         "(a JSON object with fleet_ca and hub_password)") from None
    if not isinstance(password, str) or not re.fullmatch(r"[!-~]{16,}", password):
        raise FleetError("the invitation's hub_password must be 16 or more printable characters without spaces")
    _ca_pem(ca if isinstance(ca, str) else "", "the invitation's fleet_ca")
    own = folder / "tls" / "ca.pem"
    if not own.exists():
        raise FleetError(f"{own} does not exist: start the robot's router once (it makes its CA), then join")
    joined = folder / JOINED
    joined.mkdir(parents=True, exist_ok=True)
    write_file(joined / "ca.pem", ca.encode(), 0o644)
    write_file(joined / "hub.password", password.encode() + b"\n")
    return own.read_text()


def check_robot_name(name: str) -> None:
    """A robot is named by the host of its endpoint in the hub's robot list."""
    if not _HOST.match(name):
        raise FleetError(f"robot name '{name}' must be the host of its endpoint (letters, digits, '.', '-')")


def add_robot(folder: Path, name: str, ca_pem: str) -> Path:
    """The hub's side: trust ``ca_pem`` (a robot's ``tls/ca.pem``) for the link to the
    robot reached at host ``name`` (the host of its endpoint in the hub's robot list)."""
    check_robot_name(name)
    _ca_pem(ca_pem, f"the CA given for robot '{name}'")
    path = folder / ROBOTS / f"{name}.pem"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_file(path, ca_pem.encode(), 0o644)
    return path


def robot_fleet(folder: Path) -> tuple[Path | None, dict[str, str]]:
    """On a robot's router, after :func:`ensure_tls`: the CA bundle to trust (its own CA
    plus the joined fleet CA, written to ``tls/trusted.pem``) and the fixed ``hub``
    password, or ``(None, {})`` when the robot has not joined a fleet."""
    joined = folder / JOINED
    if not (joined / "ca.pem").exists() or not (joined / "hub.password").exists():
        return None, {}
    fixed = {"hub": (joined / "hub.password").read_text().strip()}
    own = folder / "tls" / "ca.pem"
    if not own.exists():  # users only (ensure_tls comes later)
        return None, fixed
    bundle = folder / "tls" / "trusted.pem"
    write_file(bundle, own.read_bytes() + (joined / "ca.pem").read_bytes(), 0o644)
    return bundle, fixed


def hub_endpoints(folder: Path, robots: Iterable[str]) -> tuple[list[str], list[str]]:
    """The hub's connect endpoints for ``robots`` (``tls/HOST:PORT``), each with its own
    TLS settings (Zenoh's ``#`` endpoint configuration, which overrides the session's):
    the robot's CA ``robots/HOST.pem`` as the only trusted root, the fleet's ``hub``
    certificate as the client certificate.  Returns (endpoints, one-line notes about
    robots left out because their CA is missing); :class:`FleetError` on a robot
    endpoint that is not ``tls/HOST:PORT``."""
    ensure_fleet(folder)
    fleet = folder / FLEET
    out, notes = [], []
    for endpoint in robots:
        m = re.fullmatch(r"tls/([^:/?#\[\]]+):(\d{1,5})", endpoint)
        if m is None:
            raise FleetError(f"robot endpoint '{endpoint}' must be tls/HOST:PORT (a robot's router accepts TLS only)")
        ca = folder / ROBOTS / f"{m[1]}.pem"
        if not ca.exists():
            notes.append(f"robot {m[1]} ({endpoint}) left out: no {ca} yet (skinet fleet add {m[1]}, "
                         f"docs/deployment.md)")
            continue
        settings = {"root_ca_certificate_file": ca, "connect_certificate_file": fleet / "hub.pem",
                    "connect_private_key_file": fleet / "hub.key", "enable_mtls": "true"}
        out.append(endpoint + "#" + ";".join(f"{k}={v}" for k, v in settings.items()))
    return out, notes
