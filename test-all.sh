#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (unit, golden, cross-crate tests; the ones that
# need ../shared/data skip with a printed reason when it is absent).
set -euo pipefail
cd "$(dirname "$0")"
cargo test --workspace
