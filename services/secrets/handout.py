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
``tls/trusted.pem``).  A user's files are checked by
:func:`services.common.client_files.client_files`.
Cost: a few kilobytes read and compared per service.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from services.common.security import FLEET, USERS, write_file
from skinet.errors import SkinetError

ROUTER = "router"


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
