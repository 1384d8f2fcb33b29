#!/usr/bin/env bash
# Builds the project's Rust workspace (Cargo.toml at the repository root): the
# example client and the zenoh-plugin-ros2dds runner used by the DDS tests.
#
# The target directory is outside the checkout, shared by every clone on the
# machine: ${XDG_CACHE_HOME:-~/.cache}/skinet-live/cargo-target (override with
# CARGO_TARGET_DIR). cargo rebuilds only what changed, so a second run is a
# no-op of about a second. Extra arguments go to `cargo build` (e.g. --release).
# A clean debug build needs cmake and libclang-dev (scripts/install-test-deps.sh).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/skinet-live/cargo-target}"
exec nice cargo build --locked --workspace --manifest-path "$root/Cargo.toml" "$@"
