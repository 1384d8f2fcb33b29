#!/bin/sh
# Container entry point: `skinet-entrypoint SERVICE [ARGS...]`.
#
#   router                      skinet router ARGS
#   monitor | predictor | simulator | dashboard | bridge_ros2 (or bridge)
#                               python -m services.SERVICE ARGS
#   skinet                      the skinet command line
#   anything else               run as given
#
# Zenoh settings come from the SKINET_ZENOH_* variables that every service reads.
# SKINET_ZENOH_USER with SKINET_ZENOH_PASSWORD (or SKINET_ZENOH_PASSWORD_FILE, for
# Docker secrets) adds user/password authentication to the session's configuration
# (on top of SKINET_ZENOH_CONFIG when that is set).  Clients also wait for their
# router instead of failing when it is not up yet.
set -eu

if [ $# -eq 0 ] || [ "$1" = "--help" ] || [ "$1" = "-h" ]; then
    sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
    exit 0
fi

service="$1"
shift

if [ "$service" != "router" ] && [ "$service" != "skinet" ]; then
    # Written as JSON through Zenoh's own parser so that any JSON5 file given in
    # SKINET_ZENOH_CONFIG is kept, and passwords need no shell quoting.
    generated="${TMPDIR:-/tmp}/skinet-zenoh-$$.json"
    python3 - "$generated" <<'PY'
import json, os, sys
import zenoh

base = os.environ.get("SKINET_ZENOH_CONFIG")
config = zenoh.Config.from_file(base) if base else zenoh.Config()
user = os.environ.get("SKINET_ZENOH_USER", "")
password = os.environ.get("SKINET_ZENOH_PASSWORD", "")
password_file = os.environ.get("SKINET_ZENOH_PASSWORD_FILE", "")
if password_file:
    with open(password_file, encoding="utf-8") as f:
        password = f.read().strip()
if user:
    config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    config.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
if os.environ.get("SKINET_ZENOH_MODE", "client") == "client":
    config.insert_json5("connect/timeout_ms", "-1")  # wait for the router, retrying
fd = os.open(sys.argv[1], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
with os.fdopen(fd, "w") as f:
    f.write(str(config))
PY
    export SKINET_ZENOH_CONFIG="$generated"
fi

case "$service" in
    router) exec skinet router "$@" ;;
    skinet) exec skinet "$@" ;;
    bridge|bridge_ros2) exec python3 -m services.bridge_ros2 "$@" ;;
    monitor|predictor|simulator|dashboard) exec python3 -m "services.$service" "$@" ;;
    *) exec "$service" "$@" ;;
esac
