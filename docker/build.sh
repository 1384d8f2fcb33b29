#!/usr/bin/env bash
# Build the SkiNet Live image from the repository's Dockerfile.
#
#   docker/build.sh [--local-base] [--tag skinet-live:local] [--force] [-- EXTRA docker build ARGS]
#
# Wheels for the project and every dependency are built on the host, kept in
# ~/.cache/skinet-live/wheels and linked into docker/wheels/ (the image installs
# them offline, so no registry is needed inside a build).  --local-base first
# builds skinet-base:local with docker/base-image.sh and uses it as BASE_IMAGE
# (machines without a container registry); otherwise BASE_IMAGE comes from
# $SKINET_BASE_IMAGE or the Dockerfile's default.  The image carries a label with
# a hash of its inputs; when the tag already has the same hash, nothing is built.
set -euo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
tag="${SKINET_IMAGE:-skinet-live:local}"
base="${SKINET_BASE_IMAGE:-}"
python="${PYTHON:-python3}"
extra=()
force=0
cache="${SKINET_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/skinet-live}"

while [ $# -gt 0 ]; do
    case "$1" in
        --local-base) base="skinet-base:local" ;;
        --tag) tag="$2"; shift ;;
        --force) force=1 ;;
        --) shift; extra=("$@"); break ;;
        -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "build.sh: unknown argument '$1'" >&2; exit 2 ;;
    esac
    shift
done

# One build at a time per machine (parallel test workers share the images, the
# wheel cache and docker/wheels/): the others wait, then find the image up to date.
mkdir -p "$cache"
exec 9>"$cache/build.lock"
flock 9

if [ "$base" = "skinet-base:local" ]; then
    docker/base-image.sh --tag "$base"
fi

# Wheels must match the image's interpreter (CPython 3.11).
if ! "$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    if command -v python3.11 >/dev/null 2>&1; then python=python3.11; else
        echo "build.sh: wheels need CPython 3.11 on the host (set PYTHON=...)" >&2; exit 1
    fi
fi

# Everything the image is made of: the files of the build context and of the
# project wheel (not README.md: only the wheel's description), this script, the
# base image and the build arguments.
inputs() {
    {
        find Dockerfile .dockerignore pyproject.toml setup.py skinet skinet_cli services skillsets examples/nav2 docker/zenoh \
            docker/entrypoint.sh docker/build.sh -type f ! -path '*/__pycache__/*' ! -name '*.pyc' -print0 \
            | LC_ALL=C sort -z | xargs -0 sha256sum
        echo "base=${base:-default} $( [ -n "$base" ] && docker image inspect --format '{{.Id}}' "$base" 2>/dev/null)"
        echo "extra=${extra[*]-}"
        "$python" -c 'import sys; print(sys.version)'
    } | sha256sum | cut -c1-64
}
hash="$(inputs)"
if [ "$force" = 0 ] && [ "$(docker image inspect --format '{{index .Config.Labels "skinet.inputs"}}' "$tag" 2>/dev/null)" = "$hash" ]; then
    echo "build.sh: $tag is up to date (inputs ${hash:0:12}); --force rebuilds"
    exit 0
fi

# The project wheel goes to its own folder so that the image layer holding the
# dependencies stays cached while only the project changes.  A fixed
# SOURCE_DATE_EPOCH makes the wheel byte-identical for identical sources, so an
# unchanged project hits the cache too.
wheels="$cache/wheels"
mkdir -p "$wheels/project"
rm -f "$wheels"/skinet_live-*.whl "$wheels"/project/*.whl
export SOURCE_DATE_EPOCH=315532800 PIP_DISABLE_PIP_VERSION_CHECK=1
# Offline first (every dependency and build requirement already has a wheel
# here); the package index only when something is missing or a requirement changed.
offline=(--no-index --find-links "$wheels" --find-links "$wheels/build")
if ! "$python" -m pip wheel --quiet "${offline[@]}" . -w "$wheels" 2>/dev/null; then
    echo "build.sh: fetching wheels from the package index"
    build_requires="$("$python" -c 'import tomllib; print(*tomllib.load(open("pyproject.toml", "rb"))["build-system"]["requires"], sep="\n")')"
    mapfile -t build_requires <<<"$build_requires"
    "$python" -m pip download --quiet --only-binary=:all: --dest "$wheels/build" "${build_requires[@]}"
    "$python" -m pip wheel --quiet --find-links "$wheels" . -w "$wheels"
fi
mv "$wheels"/skinet_live-*.whl "$wheels/project/"
# The project's runtime requirements (from the wheel's metadata), for the image's
# dependency layer; older wheels left in the folder are then simply not chosen.
"$python" - "$wheels" <<'PY'
import pathlib, sys, zipfile
wheels = pathlib.Path(sys.argv[1])
(whl,) = (wheels / "project").glob("skinet_live-*.whl")
with zipfile.ZipFile(whl) as z:
    meta = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
    lines = z.read(meta).decode().splitlines()
reqs = [l.split(":", 1)[1].strip() for l in lines if l.startswith("Requires-Dist:") and "extra ==" not in l]
(wheels / "requirements.txt").write_text("\n".join(reqs) + "\n")
PY
rm -rf "$root/build"  # setuptools' scratch folder
# The build context needs the wheels under docker/wheels: hard links to the cache
# (copies across file systems).
rm -rf "$root/docker/wheels"
mkdir -p "$root/docker/wheels/project"
for f in "$wheels"/*.whl "$wheels"/requirements.txt "$wheels"/project/*.whl; do
    rel="${f#"$wheels"/}"
    ln -f "$f" "$root/docker/wheels/$rel" 2>/dev/null || cp -f "$f" "$root/docker/wheels/$rel"
done

args=(--tag "$tag" --label "skinet.inputs=$hash")
if [ -n "$base" ]; then args+=(--build-arg "BASE_IMAGE=$base"); fi
# A BASE_IMAGE that exists only locally needs no registry (checked with the
# classic builder, which `docker build` falls back to without buildx).
docker build "${args[@]}" "${extra[@]}" -f Dockerfile .
docker run --rm "$tag" skinet --version >/dev/null  # the image runs
# Earlier builds' images, untagged now, would pile up (about 0.5 GB per code change):
# remove the dangling ones of other inputs (what they share with this image stays).
for id in $(docker images -q --filter dangling=true --filter label=skinet.inputs); do
    if [ "$(docker image inspect --format '{{index .Config.Labels "skinet.inputs"}}' "$id")" != "$hash" ]; then
        docker rmi "$id" >/dev/null 2>&1 || true
    fi
done
docker image ls "$tag"
