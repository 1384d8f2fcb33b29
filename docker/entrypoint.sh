#!/bin/sh
# Container entry point: `skinet-entrypoint SERVICE [ARGS...]`.
#
#   router                      skinet router ARGS
#   monitor | predictor | pilot | simulator | dashboard | bridge_ros2 (or bridge)
#                               python -m services.SERVICE ARGS
#   secrets                     python -m services.secrets ARGS (compose's one-shot job)
#   skinet                      the skinet command line
#   anything else               run as given
#
# Zenoh settings come from the SKINET_ZENOH_* variables that every service reads.
# SKINET_ZENOH_USER with SKINET_ZENOH_PASSWORD (or SKINET_ZENOH_PASSWORD_FILE, for
# Docker secrets; default $SKINET_SECRETS/<user>.password, which the job `secrets`
# hands out) adds user/password authentication to the session's configuration
# (on top of SKINET_ZENOH_CONFIG when that is set), also for a router that logs in
# to other routers (with SKINET_ZENOH_CONNECT).  A tls/ endpoint in
# SKINET_ZENOH_CONNECT adds the CA and the user's certificate from
# $SKINET_SECRETS/tls/.  Clients wait for these files and for their router instead
# of failing when they are not there yet (SKINET_ZENOH_CONNECT_TIMEOUT seconds,
# default 60; -1: forever).
set -eu

if [ $# -eq 0 ] || [ "$1" = "--help" ] || [ "$1" = "-h" ]; then
    sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
    exit 0
fi

service="$1"
shift

# Services that open a Zenoh session get the generated configuration; a router only
# when it logs in somewhere itself (SKINET_ZENOH_USER set). The fleet's hub does not
# need it: `skinet router --robots` (SKINET_FLEET_ROBOTS) makes its logins and
# per-robot TLS settings itself.
case "$service" in
    monitor|predictor|pilot|simulator|dashboard|bridge|bridge_ros2) session=1 ;;
    router) session="${SKINET_ZENOH_USER:+1}" ;;
    *) session= ;;
esac
if [ -n "$session" ]; then
    # Written as JSON through Zenoh's own parser so that any JSON5 file given in
    # SKINET_ZENOH_CONFIG is kept, and passwords need no shell quoting.
    generated="${TMPDIR:-/tmp}/skinet-zenoh-$$.json"
    python3 - "$generated" <<'PY'
import json, os, sys, time
from pathlib import Path
import zenoh
from services.common.security import tls_connect_config
from services.common.environment import EnvironmentVariableError, check_environment

try:
    check_environment()  # a misspelt SKINET_ variable or a bad value: one line, before anything waits
except EnvironmentVariableError as exc:
    sys.exit(f"skinet-entrypoint: error: {exc}")

def wait_for(path):
    deadline = time.monotonic() + 120
    while not path.exists():
        if time.monotonic() > deadline:
            sys.exit(f"skinet-entrypoint: {path} never appeared (does the router run with the same secrets?)")
        time.sleep(0.5)
    return path

base = os.environ.get("SKINET_ZENOH_CONFIG")
config = zenoh.Config.from_file(base) if base else zenoh.Config()
secrets = Path(os.environ.get("SKINET_SECRETS", "/var/lib/skinet/secrets"))
user = os.environ.get("SKINET_ZENOH_USER", "")
password = os.environ.get("SKINET_ZENOH_PASSWORD", "")
password_file = os.environ.get("SKINET_ZENOH_PASSWORD_FILE", "")
if user and not password and not password_file:
    password_file = str(secrets / f"{user}.password")
if password_file:
    password = wait_for(Path(password_file)).read_text(encoding="utf-8").strip()
if user:
    config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    config.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
mode = os.environ.get("SKINET_ZENOH_MODE", "client")
if mode == "client":
    # Wait for the router, retrying; give up after a while (a wrong endpoint then shows
    # as a one-line error in the log, and the restart policy tries again).
    seconds = float(os.environ.get("SKINET_ZENOH_CONNECT_TIMEOUT", "60"))
    config.insert_json5("connect/timeout_ms", str(-1 if seconds < 0 else int(seconds * 1000)))
connect = [e.strip() for e in os.environ.get("SKINET_ZENOH_CONNECT", "").split(",") if e.strip()]
if mode == "router" and connect:  # clients read SKINET_ZENOH_CONNECT themselves
    config.insert_json5("connect/endpoints", json.dumps(connect))
if user and any(e.startswith("tls/") for e in connect):
    wait_for(secrets / "tls" / f"{user}.key")
    config.insert_json5("transport/link/tls", json.dumps(tls_connect_config(secrets / "tls", user)))
fd = os.open(sys.argv[1], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
with os.fdopen(fd, "w") as f:
    f.write(str(config))
PY
    export SKINET_ZENOH_CONFIG="$generated"
fi

case "$service" in
    router) exec skinet router "$@" ;;
    secrets) exec python3 -m services.secrets "$@" ;;
    skinet) exec skinet "$@" ;;
    bridge|bridge_ros2) exec python3 -m services.bridge_ros2 "$@" ;;
    monitor|predictor|pilot|simulator|dashboard) exec python3 -m "services.$service" "$@" ;;
    *) exec "$service" "$@" ;;
esac
