#!/usr/bin/env bash
# The whole test suite, from a fresh clone: builds everything and runs every test.
# Tests that need ../shared/data/bandai2 print why they have nothing to check when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
# The CLI tests in tests/ run the `zoo` binary itself.
cargo build --workspace --bins
cargo test --workspace --all-targets "$@"
