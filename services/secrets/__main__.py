"""``python -m services.secrets``: compose's one-shot job ``secrets`` (issue 25 item 7; docs/deployment.md).

It is the only container that mounts the vault, which holds the CA key, and it
has no network: it makes what is missing there (passwords, the CA, a certificate
per name; on a fleet's hub the fleet CA and the hub's link certificate), hands
each service's folder its own files (:func:`services.secrets.handout.hand_out`)
and exits, before the router and the services start.
"""

from __future__ import annotations

import os
from pathlib import Path

from services.common.cli import one_line_errors
from services.common.security import USERS, ensure_fleet, ensure_tls, ensure_users
from services.secrets.handout import ROUTER, hand_out
from skinet.errors import SkinetError
from services.common.options import ArgumentParser

PROG = "python -m services.secrets"


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog=PROG,
        description="Make what is missing in the vault (a password per user, a CA, a certificate for the router "
                    "and each user; with --fleet-hub the fleet CA and the hub's link certificate), then copy into "
                    "each folder of --out, named router or for a user, only that service's files (never the CA "
                    "key); an --out that does not exist yet is made with a folder for the router and each user. Compose runs it "
                    "before every start; existing files are kept.")
    parser.add_argument("--vault", default=os.environ.get("SKINET_SECRETS", "/var/lib/skinet/secrets"),
                        help="the folder of every secret (default: $SKINET_SECRETS or /var/lib/skinet/secrets)")
    parser.add_argument("--out", default="/var/lib/skinet/out",
                        help="folder of one folder per service: router, or a user's name (default: /var/lib/skinet/out)")
    parser.add_argument("--hostnames", default=os.environ.get("SKINET_TLS_HOSTNAMES", ""), metavar="NAMES",
                        help="names clients reach the router by (comma-separated), put into certificates made now "
                             "(default: $SKINET_TLS_HOSTNAMES)")
    parser.add_argument("--fleet-hub", action="store_true",
                        help="also the fleet CA and the hub's link certificate and password (fleet/)")
    return parser


@one_line_errors(PROG)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    vault, out = Path(args.vault), Path(args.out)
    if out.exists() and not out.is_dir():
        raise SkinetError(f"--out {out} is not a folder")
    vault.mkdir(mode=0o700, parents=True, exist_ok=True)
    if not out.exists():  # outside compose, which mounts one folder per service: one for each of them
        for name in (ROUTER, *USERS):
            (out / name).mkdir(mode=0o700, parents=True)
    ensure_users(vault)
    ensure_tls(vault / "tls", [ROUTER, *USERS], [h.strip() for h in args.hostnames.split(",") if h.strip()])
    if args.fleet_hub:
        ensure_fleet(vault)
    # The goal box's operator login is handed out only when the dashboard is told to use it: by default the
    # dashboard's container holds no operator credentials.
    withheld = frozenset() if os.environ.get("SKINET_DASHBOARD_GOAL_USER") == "goalbox" else frozenset({"goalbox"})
    for name, files in hand_out(vault, out, withheld).items():
        print(f"secrets: {name}: {' '.join(files) or '(nothing: not switched on)'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
