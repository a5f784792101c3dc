#!/usr/bin/env bash
# The whole test suite, from a fresh clone: builds everything and runs every test.
# Tests that need ../shared/data/bandai2 print why they have nothing to check when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
# The parity tests in tests/ load onnxruntime (ort, load-dynamic): provision the library
# from the PyPI wheel into .onnxruntime/ (a no-op when it is there).
bash scripts/onnxruntime.sh >/dev/null
# The CLI tests in tests/ run the `zoo` binary itself.
cargo build --workspace --bins
cargo test --workspace --all-targets "$@"
