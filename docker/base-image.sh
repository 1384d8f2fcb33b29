#!/usr/bin/env bash
# Build a local Debian bookworm base image with Python 3.11 without any container
# registry: debootstrap a minimal root filesystem and `docker import` it.
#
#   docker/base-image.sh [--force] [--tag skinet-base:local] [--mirror URL]
#
# Skips the build when the tag exists and was made by this version of the script
# (a label holds its hash; --force rebuilds anyway).  Needs root (or sudo), a
# Debian mirror and debootstrap (installed with apt-get when missing).
set -euo pipefail

tag="${SKINET_BASE_TAG:-skinet-base:local}"
mirror="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
suite=bookworm
force=0

while [ $# -gt 0 ]; do
    case "$1" in
        --force) force=1 ;;
        --tag) tag="$2"; shift ;;
        --mirror) mirror="$2"; shift ;;
        -h|--help) sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "base-image.sh: unknown argument '$1'" >&2; exit 2 ;;
    esac
    shift
done

hash="$(sha256sum <"$0" | cut -c1-64)"
if [ "$force" = 0 ] && [ "$(docker image inspect --format '{{index .Config.Labels "skinet.inputs"}}' "$tag" 2>/dev/null)" = "$hash" ]; then
    echo "base-image.sh: $tag is up to date (use --force to rebuild)"
    exit 0
fi

sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
if ! command -v debootstrap >/dev/null 2>&1 && [ ! -x /usr/sbin/debootstrap ]; then
    if command -v apt-get >/dev/null 2>&1; then
        echo "base-image.sh: installing debootstrap"
        $sudo apt-get update -qq && $sudo apt-get install -y -qq debootstrap >/dev/null
    else
        echo "base-image.sh: debootstrap not found (Debian/Ubuntu: apt-get install debootstrap)" >&2
        exit 1
    fi
fi
export PATH="$PATH:/usr/sbin:/sbin"

rootfs="$(mktemp -d "${TMPDIR:-/tmp}/skinet-rootfs.XXXXXX")"
trap '$sudo rm -rf "$rootfs"' EXIT

echo "base-image.sh: debootstrap $suite into $rootfs"
$sudo debootstrap --variant=minbase --include=python3,python3-venv \
    "$suite" "$rootfs" "$mirror" >"$rootfs.log" 2>&1 || {
    tail -20 "$rootfs.log" >&2
    rm -f "$rootfs.log"
    exit 1
}
rm -f "$rootfs.log"

# Trim what a Python service never needs at run time (about a third of minbase).
$sudo rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/* \
    "$rootfs"/usr/share/doc/* "$rootfs"/usr/share/man/* "$rootfs"/usr/share/info/* \
    "$rootfs"/usr/share/locale/* "$rootfs"/var/log/*.log "$rootfs"/var/cache/debconf/*-old
$sudo find "$rootfs/usr/lib/python3.11" -name '__pycache__' -prune -exec rm -rf {} +
$sudo rm -rf "$rootfs"/usr/lib/python3.11/test "$rootfs"/usr/lib/python3.11/idlelib \
    "$rootfs"/usr/lib/python3.11/tkinter "$rootfs"/usr/lib/python3.11/turtledemo

echo "base-image.sh: importing as $tag"
$sudo tar -C "$rootfs" -c . | docker import \
    --change 'ENV LANG=C.UTF-8' \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["python3"]' \
    --change "LABEL skinet.inputs=$hash" \
    --message "debootstrap $suite minbase + python3, python3-venv" \
    - "$tag" >/dev/null
docker image ls "$tag"
