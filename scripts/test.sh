#!/usr/bin/env bash
# The whole test suite, from a fresh clone: builds everything and runs every test.
# Tests that need ../shared/data/bandai2 print why they have nothing to check when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
# The parity tests in tests/ load onnxruntime (ort, load-dynamic): provision the library
# from the PyPI wheel into .onnxruntime/ (a no-op when it is there).
bash scripts/onnxruntime.sh >/dev/null
# The Unity package's tests (tests/unity.rs) compile its C# with Mono: Debian's mono-complete,
# installed when missing and apt-get can (as root); without it those tests fail and say so.
if ! command -v mcs >/dev/null && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mono-complete >/dev/null
fi
# Debian's Blender (when installed) runs the add-on's tests on the system Python, which needs
# numpy (Debian's python3-numpy, only recommended by the blender package): installed when
# missing and apt-get can (as root); without it those tests fail and say so.
if command -v blender >/dev/null && ! /usr/bin/python3 -c "import numpy" 2>/dev/null \
  && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-numpy >/dev/null
fi
# The CLI tests in tests/ run the `zoo` binary itself.
cargo build --workspace --bins
# --no-fail-fast: every test binary runs even when one fails (the command still ends non-zero),
# so one failing test never hides the others.
cargo test --workspace --all-targets --no-fail-fast "$@"
