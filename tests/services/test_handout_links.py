"""The hand-out writes no secret through a link (issue 31, item 3).

A compromised service could plant links in the folder the job ``secrets`` writes
into; before the fix, a link at ``router/tls/router.key.tmp`` made the hand-out
overwrite the vault's ``ca.key``.  Here a link is planted at every name the
hand-out writes (and at the temporary names it once used), pointing into the
vault: each run leaves the vault byte-for-byte and mode-for-mode as it was, and
every link it would have written through is refused with one line.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from services.common.security import USERS, ensure_tls, ensure_users, write_file
from services.secrets.handout import ROUTER, hand_out, service_files, take_handed
from skinet.errors import SkinetError
from tests.services.conftest import free_port, start_skinet

REPO = Path(__file__).resolve().parents[2]


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mode) for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.fixture(scope="module")
def vault(tmp_path_factory: pytest.TempPathFactory) -> Path:
    vault = tmp_path_factory.mktemp("vault")
    ensure_users(vault)
    ensure_tls(vault / "tls", [ROUTER, *USERS])
    return vault


def planted(vault: Path) -> list[tuple[str, str, str | None]]:
    """(service, name in its folder, the error) for a link at every name the hand-out writes:
    each file, each folder on the way, the service's folder, and the old temporary names."""
    cases: list[tuple[str, str, str | None]] = []
    for service in (ROUTER, "observer"):
        for name in service_files(vault, service):
            cases.append((service, name, "{target} is a link: secrets are never written through a link"))
            cases.append((service, name + ".tmp", None))  # no longer a name it writes: the link is left alone
        cases.append((service, "tls", "{target} is a link: secrets are never written through a link"))
        cases.append((service, "", "{target} is a link: secrets are never written through a link"))
    return cases


def test_links_planted_at_every_name_leave_the_vault_unchanged(vault: Path, tmp_path: Path) -> None:
    before = snapshot(vault)
    for n, (service, name, message) in enumerate(planted(vault)):
        out = tmp_path / f"out{n}"
        target = out / service / name if name else out / service
        target.parent.mkdir(parents=True, exist_ok=True)
        if name == "tls":
            target.symlink_to(vault / "tls")  # the folder: its router.key would land on the vault's
        elif name == "":
            target.symlink_to(vault)  # the service's folder itself
        else:
            target.symlink_to(vault / "tls" / "ca.key")
        if message is None:
            hand_out(vault, out)  # the router's folder keeps it; a client's has it removed, itself
            assert target.is_symlink() == (service == ROUTER) and (vault / "tls" / "ca.key").is_file()
        else:
            with pytest.raises(SkinetError) as info:
                hand_out(vault, out)
            assert str(info.value) == message.format(target=target), (service, name)
            assert target.is_symlink()
        assert snapshot(vault) == before, (service, name)


def test_the_job_fails_in_one_line_on_a_planted_link(vault: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / ROUTER / "tls").mkdir(parents=True)
    (out / ROUTER / "tls" / "router.key").symlink_to(vault / "tls" / "ca.key")
    before = snapshot(vault)
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout, r.stderr) == (
        1, "", f"python -m services.secrets: error: {out / ROUTER / 'tls' / 'router.key'} is a link: "
               "secrets are never written through a link\n")
    assert snapshot(vault) == before


def test_write_file_replaces_a_file_and_refuses_links(tmp_path: Path) -> None:
    """The one writer of secrets and configurations (the vault, ``skinet client-config``)."""
    (tmp_path / "real").mkdir()
    (tmp_path / "victim").write_bytes(b"victim\n")
    write_file(tmp_path / "real" / "a.key", b"one\n")
    write_file(tmp_path / "real" / "a.key", b"two\n", 0o644)
    assert (tmp_path / "real" / "a.key").read_bytes() == b"two\n"
    assert (tmp_path / "real" / "a.key").stat().st_mode & 0o777 == 0o644
    assert os.listdir(tmp_path / "real") == ["a.key"]  # no temporary file left
    (tmp_path / "real" / "b.key").symlink_to(tmp_path / "victim")
    (tmp_path / "linked").symlink_to(tmp_path / "real")
    os.mkfifo(tmp_path / "real" / "pipe")
    for path, message in [(tmp_path / "real" / "b.key", "{} is a link: secrets are never written through a link"),
                          (tmp_path / "linked" / "c.key", "{} is a link: secrets are never written through a link"),
                          (tmp_path / "real" / "pipe", "{} is not a regular file: a secret is written as a file only")]:
        with pytest.raises(SkinetError) as info:
            write_file(path, b"x")
        shown = path.parent if path.parent.name == "linked" else path
        assert str(info.value) == message.format(shown)
    assert (tmp_path / "victim").read_bytes() == b"victim\n"
    assert sorted(os.listdir(tmp_path / "real")) == ["a.key", "b.key", "pipe"]


def test_the_router_copies_its_read_only_hand_out_into_its_own_folder(vault: Path, tmp_path: Path) -> None:
    """compose mounts the router's hand-out read-only (``--handed``); the router works on a copy
    in its own folder, where the job never writes, and logs in its users with it."""
    out, own = tmp_path / "out", tmp_path / "own"
    (out / ROUTER).mkdir(parents=True)
    hand_out(vault, out)
    (out / ROUTER / "tls" / "stray.pem").symlink_to(vault / "tls" / "ca.key")  # never followed
    handed = out / ROUTER
    os.chmod(handed / "tls", 0o500)
    os.chmod(handed, 0o500)  # read-only, as mounted
    try:
        assert take_handed(handed, own) == ["tls/ca.pem", "tls/router.key", "tls/router.pem", "users.txt"]
    finally:
        os.chmod(handed, 0o700)
        os.chmod(handed / "tls", 0o700)
    assert snapshot(own) == {k: v for k, v in snapshot(handed).items() if k != "tls/stray.pem"}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = start_skinet("router", "--listen", endpoint, "--secrets", str(own), "--handed", str(handed))
    try:
        assert router.stdout is not None
        line = router.stdout.readline()
        assert line.startswith("zenoh router ") and f"users and passwords in {own}" in line, line
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("transport/auth/usrpwd/user", '"observer"')
        config.insert_json5("transport/auth/usrpwd/password",
                            json.dumps((vault / "observer.password").read_text().strip()))
        zenoh.open(config).close()
    finally:
        router.send_signal(signal.SIGTERM)
        assert router.wait(timeout=10) == 0
    with pytest.raises(SkinetError) as info:
        take_handed(tmp_path / "none", own)
    assert str(info.value) == f"handed-out secrets folder {tmp_path / 'none'} does not exist"


def test_a_fifo_as_a_password_or_key_file_is_refused_not_waited_on(vault: Path, tmp_path: Path) -> None:
    """The same reader as the model files (skinet.files.read.read_bytes): nothing blocks on a FIFO."""
    import argparse

    from services.common.zenoh_config import login
    from services.common.client_files import client_files

    os.mkfifo(tmp_path / "pw")
    with pytest.raises(SkinetError) as info:
        login(argparse.Namespace(user="observer", password=None, password_file=str(tmp_path / "pw")))
    assert str(info.value) == f"cannot read password file {tmp_path / 'pw'}: not a regular file"
    out = tmp_path / "out"
    (out / "observer").mkdir(parents=True)
    hand_out(vault, out)
    key = out / "observer" / "tls" / "observer.key"
    key.unlink()
    os.mkfifo(key)
    with pytest.raises(SkinetError) as info:
        client_files(out / "observer", "observer")
    assert str(info.value) == f"cannot read {key}: not a regular file"


def test_the_goal_box_login_is_handed_out_only_when_switched_on(tmp_path: Path) -> None:
    """By default the dashboard's container holds no operator credentials: the job leaves goalbox's folder empty
    (and empties it), unless SKINET_DASHBOARD_GOAL_USER=goalbox."""
    import os
    import subprocess
    import sys

    out = tmp_path / "out"
    for name in ("observer", "goalbox"):
        (out / name).mkdir(parents=True)
    (out / "goalbox" / "stale.password").write_text("old")
    job = [sys.executable, "-m", "services.secrets", "--vault", str(tmp_path / "vault"), "--out", str(out)]
    env = {k: v for k, v in os.environ.items() if k != "SKINET_DASHBOARD_GOAL_USER"}
    off = subprocess.run(job, capture_output=True, text=True, timeout=60, env=env)
    assert off.returncode == 0, off.stderr
    assert "secrets: goalbox: (nothing: not switched on)" in off.stdout.splitlines()
    assert list((out / "goalbox").rglob("*")) == [] and (out / "observer" / "observer.password").is_file()
    on = subprocess.run(job, capture_output=True, text=True, timeout=60,
                        env={**env, "SKINET_DASHBOARD_GOAL_USER": "goalbox"})
    assert on.returncode == 0, on.stderr
    assert (out / "goalbox" / "goalbox.password").is_file() and (out / "goalbox" / "tls" / "goalbox.key").is_file()
