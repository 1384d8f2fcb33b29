"""``skinet client-config``: one user's Zenoh client configuration from a secrets folder (issue 27 item 7).

The file names the user's password, the CA and the user's certificate and key,
each checked first as the router will check them (:func:`services.secrets.handout.client_files`);
``watch``, ``dashboard``, ``check``, ``record`` and the services read it with
``--zenoh-config``.  The CA key is neither read nor named.  Arguments only: the
cryptography and Zenoh modules are imported when the command runs.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from services.common.options import key_name
from skinet.files import program

DEFAULT_ENDPOINT = "tls/127.0.0.1:7447"
OPERATOR = "operator"  # the compose vault's user of the operator role: it may send the pilot goals
HELP = "write the Zenoh client configuration (TLS, login) of one user from a deployment's secrets"
DESCRIPTION = """\
Write the Zenoh configuration with which a command logs in to a SkiNet router
as USER over mutual TLS: the password, and the paths of the CA certificate and
of USER's certificate and key, from DIR (USER.password, tls/ca.pem,
tls/USER.pem, tls/USER.key), each checked first as the router checks them (the
certificate must name USER, be signed by the CA, be valid now and match its
key). The CA key is neither read nor named. The file holds the password: it is
written with mode 0600."""
EXAMPLES = """\
examples:
  skinet client-config --secrets observer --user observer     # writes observer.json5
  skinet watch spot_arm --zenoh-config observer.json5
  skinet client-config --secrets /srv/skinet/predictor --user predictor \\
      --connect tls/robot.example:7447 -o predictor.json5
  skinet client-config --secrets operator --user operator     # an operator: may send the pilot goals
  skinet goal spot_arm "run spot:init_power" --drive --zenoh-config operator.json5

docs/deployment.md ("Host access"; "The pilot and its operators" for the
operator's) shows how to get a user's folder out of a compose deployment; the
folder of `skinet router --secrets DIR --listen tls/...` serves as it is (a
router makes the certificates, tls/ca.pem and one per user, when it listens on
a tls/ endpoint; on tcp/ only, its folder holds no certificates)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser(
        "client-config", help=HELP, epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
        description=DESCRIPTION)
    c.add_argument("--secrets", metavar="DIR",
                   default=os.environ.get("SKINET_SECRETS") or str(Path.home() / ".config" / "skinet" / "secrets"),
                   help="folder of USER's secrets: a compose service's own folder, or a router's "
                        "(default: $SKINET_SECRETS or ~/.config/skinet/secrets, as skinet router)")
    c.add_argument("--user", type=key_name("user name"), default="observer",
                   help="the router user to log in as (default: observer, which may only read and ask the check; "
                        "operator may also send the pilot goals)")
    c.add_argument("--connect", "-e", default=DEFAULT_ENDPOINT, metavar="ENDPOINT",
                   help=f"the router's tls/ endpoint as seen from where the file is used (default: {DEFAULT_ENDPOINT}, "
                        "the compose router published on this host)")
    c.add_argument("-o", "--output", metavar="FILE.json5",
                   help="the file to write, .json5 or .json (default: USER.json5 in the current folder)")
    c.set_defaults(func=cmd_client_config)


def cmd_client_config(args: argparse.Namespace) -> int:
    from services.common.security import write_file
    from services.common.endpoints import check_endpoint
    from services.common.client_files import client_config, client_files
    from skinet.errors import SkinetError

    check_endpoint(args.connect, "--connect")
    if not args.connect.startswith("tls/"):
        raise SkinetError(f"--connect '{args.connect}': the router checks certificates on a tls/ endpoint only, "
                          "e.g. tls/127.0.0.1:7447")
    output = Path(args.output or f"{args.user}.json5")
    if output.suffix not in (".json5", ".json"):
        raise SkinetError(f"{output}: the name must end with .json5 or .json (Zenoh reads the format from it)")
    folder = Path(args.secrets)
    files = client_files(folder, args.user)
    text = json.dumps(client_config(files, args.connect), indent=2) + "\n"
    if output.suffix == ".json5":
        text = (f"// Zenoh client configuration of user '{args.user}' for the router at {args.connect},\n"
                f"// written by `skinet client-config` from {folder.resolve()}.\n"
                "// It holds the password: keep it private.  Use it with --zenoh-config, e.g.\n"
                f"//   {program.skinet()} watch SYSTEM_NAME --zenoh-config {output}\n" + text)
    try:
        write_file(output, text.encode())
    except OSError as exc:
        raise SkinetError(f"cannot write {output}: {exc.strerror}") from None
    print(f"wrote {output}: user {args.user} at {args.connect} (password, CA, certificate and key of {folder})")
    print(f"  {program.skinet()} watch SYSTEM_NAME --zenoh-config {output}")
    if args.user == OPERATOR:
        print(f"  {program.skinet()} goal SYSTEM_NAME GOAL... --drive --zenoh-config {output}")
    return 0
