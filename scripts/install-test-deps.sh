#!/usr/bin/env bash
# Installs the Debian packages the test suite needs (part of `make test`).
#
# Each package is installed only when missing; without root (or apt-get) the
# script prints what is missing and the tests that need it skip with a message.
# Add a package to PACKAGES with a comment naming the tests that need it.
set -euo pipefail

PACKAGES=(
    debootstrap  # tests/deploy/test_containers.py: docker/base-image.sh makes the base image without a registry
    cmake          # cargo workspace: cyclors builds CycloneDDS (tests/dds, tests/deploy/test_rust_client.py)
    libclang-dev   # cargo workspace: cyclors generates its CycloneDDS bindings with bindgen (same tests)
    spin  # tests/net/test_promela.py: Spin's stored-state count equals ours; benchmarks/bench_big.py
    gcc   # compiles Spin's pan.c verifier (same tests)
    chromium          # tests/services/test_dashboard.py: the dashboard in a real browser
    chromium-driver   # the same, driven by selenium
    graphviz          # tests/net/test_export.py: the dot export renders
)

missing=()
for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "install-test-deps: missing Debian packages (tests needing them will skip): ${missing[*]}" >&2
    exit 0
fi
echo "install-test-deps: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
